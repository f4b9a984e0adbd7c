#include "sonoshape/simulator/bmode.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/mesh_slicer.hpp"

namespace sonoshape::simulator {
namespace {

// Smoothing (beam samples) of the impedance map whose gradient gives boundary normals.
constexpr double kNormalSmoothingPx = 1.5;
// Specular echoes fall off with the angle of incidence as cos^kSpecularPower.
constexpr double kSpecularPower = 2.0;
// Mean of a Rayleigh amplitude whose complex components have unit variance: sqrt(pi / 2).
constexpr double kRayleighMean = 1.2533141373155;
constexpr double kMinAmplitude = 1e-6;
// Speed of sound in soft tissue (mm per microsecond), for the wavelength.
constexpr double kSoundSpeedMmPerUs = 1.54;
// A tissue that loses the shadow threshold over this path (cm, one way) casts shadows on its
// own inside (bone); see render().
constexpr double kShadowCasterPathCm = 0.1;

void check_label(int label) {
  if (label < 1 || label > kMaxPixelLabel)
    throw GeometryError("label " + std::to_string(label) + " cannot be drawn in an 8-bit label " +
                        "image (use labels 1.." + std::to_string(kMaxPixelLabel) + ")");
}

}  // namespace

LabelImage rasterize_labels(const LabeledSlice& slice, const acquisition::Probe& probe) {
  LabelImage image(probe.width_px(), probe.height_px(), kLabelPixelOutside);
  std::vector<std::array<Vec2, 2>> edges;
  std::vector<double> crossings;
  for (const Region& region : slice.regions) {
    check_label(region.label);
    edges.clear();
    double top = std::numeric_limits<double>::infinity(), bottom = -top;
    auto add_ring = [&](const Ring2& ring) {
      for (std::size_t k = 0; k < ring.size(); ++k) {
        const Vec2 a = probe.mm_to_pixel(ring[k]);
        const Vec2 b = probe.mm_to_pixel(ring[(k + 1) % ring.size()]);
        edges.push_back({a, b});
        top = std::min(top, a.y());
        bottom = std::max(bottom, a.y());
      }
    };
    add_ring(region.outer);
    for (const Ring2& hole : region.holes) add_ring(hole);
    const int j_first = std::max(0, static_cast<int>(std::ceil(top)));
    const int j_last = std::min(image.height - 1, static_cast<int>(std::floor(bottom)));
    const auto value = static_cast<std::uint8_t>(region.label);
    for (int j = j_first; j <= j_last; ++j) {
      // Even-odd scanline through the pixel centres; half-open in y so a vertex on the line
      // counts once.
      const double y = j;
      crossings.clear();
      for (const auto& [a, b] : edges) {
        if ((a.y() <= y) == (b.y() <= y)) continue;
        crossings.push_back(a.x() + (y - a.y()) * (b.x() - a.x()) / (b.y() - a.y()));
      }
      std::sort(crossings.begin(), crossings.end());
      for (std::size_t k = 0; k + 1 < crossings.size(); k += 2) {
        const int i_first = std::max(0, static_cast<int>(std::ceil(crossings[k])));
        const int i_last =
            std::min(image.width - 1, static_cast<int>(std::ceil(crossings[k + 1])) - 1);
        for (int i = i_first; i <= i_last; ++i) image.at(i, j) = value;
      }
    }
  }
  return image;
}

struct BModeSimulator::Impl {
  Phantom phantom;
  acquisition::Probe probe;
  BModeOptions options;
  cv::Mat beam_to_pixel_x, beam_to_pixel_y;  // rows = samples, cols = beams: pixel coordinates
  cv::Mat pixel_to_beam_x, pixel_to_beam_y;  // rows, cols of the image: beam coordinates
  ImageU8 sector;                            // 255 inside
  std::size_t sector_pixels = 0;
  std::vector<double> depth_cm;      // per sample
  std::vector<double> lateral_step;  // per sample (mm)
  double sigma_axial_px = 1.0, sigma_lateral_px = 1.0;

  Impl(Phantom p, const acquisition::Probe& pr, const BModeOptions& o)
      : phantom(std::move(p)), probe(pr), options(o) {
    const int beams = probe.width_px(), samples = probe.height_px();
    beam_to_pixel_x.create(samples, beams, CV_32F);
    beam_to_pixel_y.create(samples, beams, CV_32F);
    for (int s = 0; s < samples; ++s)
      for (int b = 0; b < beams; ++b) {
        const Vec2 px = probe.mm_to_pixel(probe.beam_to_mm(b, s));
        beam_to_pixel_x.at<float>(s, b) = static_cast<float>(px.x());
        beam_to_pixel_y.at<float>(s, b) = static_cast<float>(px.y());
      }
    pixel_to_beam_x.create(probe.height_px(), probe.width_px(), CV_32F);
    pixel_to_beam_y.create(probe.height_px(), probe.width_px(), CV_32F);
    sector = probe.sector_mask();
    for (int j = 0; j < probe.height_px(); ++j)
      for (int i = 0; i < probe.width_px(); ++i) {
        const Vec2 beam = probe.mm_to_beam(probe.pixel_to_mm(i, j));
        pixel_to_beam_x.at<float>(j, i) = static_cast<float>(beam.x());
        pixel_to_beam_y.at<float>(j, i) = static_cast<float>(beam.y());
        if (sector.at(i, j)) ++sector_pixels;
      }
    for (int s = 0; s < samples; ++s) {
      depth_cm.push_back(0.1 * probe.sample_depth_mm(s));
      lateral_step.push_back(probe.lateral_step_mm(s));
    }
    const double wavelength_mm = kSoundSpeedMmPerUs / probe.geometry().frequency_mhz;
    sigma_axial_px = options.psf_axial_wavelengths * wavelength_mm / probe.axial_step_mm();
    sigma_lateral_px =
        options.psf_lateral_wavelengths * wavelength_mm / probe.lateral_step_mm(0.5 * samples);
  }

  // Per-label acoustic properties (label 0: background) and their per-sample factors.
  struct Acoustics {
    std::array<float, 256> echo{}, impedance{}, attenuation{};
    double frequency_mhz = 0.0, background_db_per_cm = 0.0;
    // Gains advance by one factor per sample (cheaper than a pow per sample): the tissue's
    // round-trip attenuation over one step, and time-gain compensation's growth.
    std::array<double, 256> step_loss_db{}, step_factor{};
    double tgc_db_per_cm = 0.0, tgc_step_factor = 1.0;
  };
  // The echo field along the beams (two components per sample) and where the beams are shadowed.
  struct BeamField {
    cv::Mat field;   // samples x beams, CV_32FC2
    cv::Mat shadow;  // samples x beams, 255 where the loss passed the shadow threshold
  };

  SimulatedFrame render(const Eigen::Isometry3d& T_reference_probe, std::uint64_t seed) const;
  Acoustics acoustics() const;
  bool casts_shadow(int label) const;
  // The boundary normals' components (along the beams' lateral and axial directions) from the
  // smoothed impedance map.
  void boundary_gradients(const cv::Mat& beam_labels, const Acoustics& a, cv::Mat& grad_b,
                          cv::Mat& grad_s) const;
  // Walks down every beam: specular echoes at boundaries, cumulative loss, shadows.
  BeamField walk_beams(const cv::Mat& beam_labels, const Acoustics& a, std::uint64_t seed) const;
  // Point-spread function, envelope, log compression to grey (samples x beams, CV_32F).
  cv::Mat envelope_grey(cv::Mat& field) const;
  // Scan conversion into `frame` (B-mode, labels, truth, shadow); outside the sector is black
  // (grey) and unknown (labels).
  void scan_convert(const cv::Mat& grey_beam, const cv::Mat& shadow, const LabelImage& labels,
                    SimulatedFrame& frame) const;
};

SimulatedFrame BModeSimulator::Impl::render(const Eigen::Isometry3d& T_reference_probe,
                                            std::uint64_t seed) const {
  SimulatedFrame frame;
  SlicePlane plane;
  plane.origin_mm = T_reference_probe.translation();
  plane.u = T_reference_probe.linear().col(0);
  plane.v = T_reference_probe.linear().col(1);
  frame.slice = slice_meshes(phantom.meshes, plane);
  frame.slice.fov = probe.sector_ring_mm();
  const LabelImage labels = rasterize_labels(frame.slice, probe);
  const cv::Mat label_mat(labels.height, labels.width, CV_8U,
                          const_cast<std::uint8_t*>(labels.pixels.data()));
  cv::Mat beam_labels;
  cv::remap(label_mat, beam_labels, beam_to_pixel_x, beam_to_pixel_y, cv::INTER_NEAREST,
            cv::BORDER_REPLICATE);
  const Acoustics a = acoustics();
  BeamField beams = walk_beams(beam_labels, a, seed);
  const cv::Mat grey_beam = envelope_grey(beams.field);
  scan_convert(grey_beam, beams.shadow, labels, frame);
  return frame;
}

BModeSimulator::Impl::Acoustics BModeSimulator::Impl::acoustics() const {
  Acoustics a;
  for (int l = 0; l < 256; ++l) {
    const Tissue t = l == 0 ? phantom.background : phantom.tissue(l);
    a.echo[l] = static_cast<float>(t.echogenicity);
    a.impedance[l] = static_cast<float>(t.impedance_mrayl);
    a.attenuation[l] = static_cast<float>(t.attenuation_db_per_cm_mhz);
  }
  a.frequency_mhz = probe.geometry().frequency_mhz;
  a.background_db_per_cm = 2.0 * phantom.background.attenuation_db_per_cm_mhz * a.frequency_mhz;
  const double step_cm = 0.1 * probe.axial_step_mm();
  for (int l = 0; l < 256; ++l) {
    a.step_loss_db[l] = 2.0 * a.attenuation[l] * a.frequency_mhz * step_cm;
    a.step_factor[l] = std::pow(10.0, -a.step_loss_db[l] / 20.0);
  }
  a.tgc_db_per_cm = options.tgc_fraction * a.background_db_per_cm;
  a.tgc_step_factor = std::pow(10.0, a.tgc_db_per_cm * step_cm / 20.0);
  return a;
}

bool BModeSimulator::Impl::casts_shadow(int label) const {
  // In single precision, as the beams' attenuation (Acoustics) is.
  const float attenuation = static_cast<float>(phantom.tissue(label).attenuation_db_per_cm_mhz);
  return 2.0 * attenuation * probe.geometry().frequency_mhz * kShadowCasterPathCm >=
         options.shadow_threshold_db;
}

void BModeSimulator::Impl::boundary_gradients(const cv::Mat& beam_labels, const Acoustics& a,
                                              cv::Mat& grad_b, cv::Mat& grad_s) const {
  const int beams = probe.width_px(), samples = probe.height_px();
  cv::Mat z_map(samples, beams, CV_32F);
  for (int s = 0; s < samples; ++s) {
    const std::uint8_t* row = beam_labels.ptr<std::uint8_t>(s);
    float* out = z_map.ptr<float>(s);
    for (int b = 0; b < beams; ++b) out[b] = a.impedance[row[b]];
  }
  cv::GaussianBlur(z_map, z_map, cv::Size(0, 0), kNormalSmoothingPx);
  cv::Sobel(z_map, grad_b, CV_32F, 1, 0);
  cv::Sobel(z_map, grad_s, CV_32F, 0, 1);
}

BModeSimulator::Impl::BeamField BModeSimulator::Impl::walk_beams(const cv::Mat& beam_labels,
                                                                 const Acoustics& a,
                                                                 std::uint64_t seed) const {
  const int beams = probe.width_px(), samples = probe.height_px();
  cv::Mat grad_b, grad_s;
  boundary_gradients(beam_labels, a, grad_b, grad_s);
  BeamField out{cv::Mat(samples, beams, CV_32FC2), cv::Mat(samples, beams, CV_8U, cv::Scalar(0))};
  cv::RNG rng(seed ^ 0x9E3779B97F4A7C15ull);
  rng.fill(out.field, cv::RNG::NORMAL, 0.0, 1.0);
  const float speckle_norm =
      static_cast<float>(std::sqrt(4.0 * std::numbers::pi * sigma_axial_px * sigma_lateral_px));
  const double impulse_norm =
      std::sqrt(2.0 * std::numbers::pi) * sigma_axial_px * kRayleighMean * options.specular_gain;
  const double axial_step = probe.axial_step_mm();
  std::vector<double> loss_db(static_cast<std::size_t>(beams), 0.0);
  std::vector<double> gain(
      static_cast<std::size_t>(beams),
      std::pow(10.0, (a.tgc_db_per_cm * depth_cm[0] + options.gain_db) / 20.0));
  std::vector<std::uint8_t> previous(static_cast<std::size_t>(beams), 0);
  for (int s = 0; s < samples; ++s) {
    const std::uint8_t* row = beam_labels.ptr<std::uint8_t>(s);
    cv::Vec2f* field = out.field.ptr<cv::Vec2f>(s);
    std::uint8_t* shadow_row = out.shadow.ptr<std::uint8_t>(s);
    const double background_loss_db = a.background_db_per_cm * depth_cm[s];
    for (int b = 0; b < beams; ++b) {
      const std::size_t beam = static_cast<std::size_t>(b);
      const std::uint8_t l = row[b];
      double specular = 0.0;
      double transmission = 1.0;
      if (l != previous[beam]) {
        const double z1 = a.impedance[previous[beam]], z2 = a.impedance[l];
        const double r = (z2 - z1) / (z2 + z1);
        const double gb = grad_b.at<float>(s, b) / lateral_step[static_cast<std::size_t>(s)];
        const double gs = grad_s.at<float>(s, b) / axial_step;
        const double norm = std::hypot(gb, gs);
        const double incidence = norm > 0.0 ? std::abs(gs) / norm : 1.0;
        specular = impulse_norm * std::abs(r) * std::pow(incidence, kSpecularPower);
        transmission = std::max(1.0 - r * r, 1e-12);  // intensity there and back: amplitude
        loss_db[beam] -= 20.0 * std::log10(transmission);
        previous[beam] = l;
      }
      const auto g = static_cast<float>(gain[beam]);
      const float scatter = a.echo[l] * speckle_norm;
      field[b][0] = g * (scatter * field[b][0] + static_cast<float>(specular));
      field[b][1] = g * scatter * field[b][1];
      loss_db[beam] += a.step_loss_db[l];
      gain[beam] *= transmission * a.step_factor[l] * a.tgc_step_factor;
      if (loss_db[beam] - background_loss_db > options.shadow_threshold_db) shadow_row[b] = 255;
    }
  }
  return out;
}

cv::Mat BModeSimulator::Impl::envelope_grey(cv::Mat& field) const {
  const int beams = probe.width_px(), samples = probe.height_px();
  cv::GaussianBlur(field, field, cv::Size(0, 0), sigma_lateral_px, sigma_axial_px);
  cv::Mat grey_beam(samples, beams, CV_32F);
  // grey = (20 log10 |A| + range) * 255 / range, with 20 log10 |A| = 10 log10(2) log2 |A|^2.
  const float db_to_grey = static_cast<float>(255.0 / options.dynamic_range_db);
  const float log2_power_to_db = static_cast<float>(10.0 * std::log10(2.0));
  const float range_db = static_cast<float>(options.dynamic_range_db);
  constexpr float kMinPower = static_cast<float>(kMinAmplitude * kMinAmplitude);
  for (int s = 0; s < samples; ++s) {
    const cv::Vec2f* row = field.ptr<cv::Vec2f>(s);
    float* out = grey_beam.ptr<float>(s);
    for (int b = 0; b < beams; ++b) {
      const float power = std::max(row[b][0] * row[b][0] + row[b][1] * row[b][1], kMinPower);
      out[b] = (log2_power_to_db * std::log2(power) + range_db) * db_to_grey;
    }
  }
  return grey_beam;
}

void BModeSimulator::Impl::scan_convert(const cv::Mat& grey_beam, const cv::Mat& shadow,
                                        const LabelImage& labels, SimulatedFrame& frame) const {
  cv::Mat grey_image, shadow_image;
  cv::remap(grey_beam, grey_image, pixel_to_beam_x, pixel_to_beam_y, cv::INTER_LINEAR,
            cv::BORDER_REPLICATE);
  cv::remap(shadow, shadow_image, pixel_to_beam_x, pixel_to_beam_y, cv::INTER_NEAREST,
            cv::BORDER_REPLICATE);
  const int width = probe.width_px(), height = probe.height_px();
  frame.bmode = GreyImage(width, height, 0);
  frame.labels = labels;
  frame.truth = labels;
  frame.shadow = ImageU8(width, height, 0);
  // An organ that loses the shadow threshold within a millimetre (bone) shadows its own inside:
  // it stays its label in the truth, since its surface echo shows where it is and its extent
  // below the surface is anatomy (a rib's thickness) that a segmenter is told, not shown.
  std::array<bool, 256> casts_shadow{};
  for (int l = 1; l < 255; ++l) casts_shadow[static_cast<std::size_t>(l)] = Impl::casts_shadow(l);
  std::size_t shadow_pixels = 0;
  for (int j = 0; j < height; ++j) {
    const float* grey_row = grey_image.ptr<float>(j);
    const std::uint8_t* shadow_row = shadow_image.ptr<std::uint8_t>(j);
    for (int i = 0; i < width; ++i) {
      if (!sector.at(i, j)) {
        frame.labels.at(i, j) = kLabelPixelUnknown;
        frame.truth.at(i, j) = kLabelPixelUnknown;
        continue;
      }
      frame.bmode.at(i, j) =
          static_cast<std::uint8_t>(std::clamp(std::lround(grey_row[i]), 0L, 255L));
      if (shadow_row[i]) {
        frame.shadow.at(i, j) = 255;
        if (!casts_shadow[labels.at(i, j)]) frame.truth.at(i, j) = kLabelPixelUnknown;
        ++shadow_pixels;
      }
    }
  }
  frame.shadow_fraction =
      sector_pixels ? static_cast<double>(shadow_pixels) / static_cast<double>(sector_pixels) : 0;
}

LabelImage SimulatedFrame::visible_truth() const {
  LabelImage out = truth;
  for (std::size_t p = 0; p < out.pixels.size(); ++p)
    if (shadow.pixels[p]) out.pixels[p] = kLabelPixelUnknown;
  return out;
}

BModeSimulator::BModeSimulator(Phantom phantom, const acquisition::Probe& probe,
                               const BModeOptions& options) {
  if (phantom.meshes.empty()) throw GeometryError("B-mode simulator: the phantom has no meshes");
  for (const auto& m : phantom.meshes) check_label(m.label);
  impl_ = std::make_unique<Impl>(std::move(phantom), probe, options);
}

BModeSimulator::~BModeSimulator() = default;
BModeSimulator::BModeSimulator(BModeSimulator&&) noexcept = default;
BModeSimulator& BModeSimulator::operator=(BModeSimulator&&) noexcept = default;

const Phantom& BModeSimulator::phantom() const { return impl_->phantom; }
const acquisition::Probe& BModeSimulator::probe() const { return impl_->probe; }
const BModeOptions& BModeSimulator::options() const { return impl_->options; }

bool BModeSimulator::casts_shadow(int label) const {
  check_label(label);
  return impl_->casts_shadow(label);
}

double BModeSimulator::psf_sigma_mm() const {
  const double wavelength_mm = kSoundSpeedMmPerUs / impl_->probe.geometry().frequency_mhz;
  return 0.5 * (impl_->options.psf_lateral_wavelengths + impl_->options.psf_axial_wavelengths) *
         wavelength_mm;
}

SimulatedFrame BModeSimulator::render(const Eigen::Isometry3d& T_reference_probe,
                                      std::uint64_t seed) const {
  return impl_->render(T_reference_probe, seed);
}

}  // namespace sonoshape::simulator
