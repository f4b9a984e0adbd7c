// Writes the segmentation pictures of docs/: a simulated B-mode frame, its ground truth and its
// segmentation (label map with the slice's polygons drawn on it) side by side, for a linear and
// a convex probe (docs/images/seg_linear.png, seg_convex.png). Run from anywhere:
//   cmake --build build --target sonoshape_seg_images && build/segmentation/sonoshape_seg_images
// The models come from the header of a short simulated sweep around the pictured plane, as
// `sonoshape segment` takes them from a `sonoshape simulate` sweep.
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/png_file.hpp"
#include "sonoshape/segmentation/contours.hpp"
#include "sonoshape/segmentation/segmenter.hpp"
#include "sonoshape/segmentation/sweep.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace {

using namespace sonoshape;

constexpr int kGapPx = 8;

// Label colours (BGR), as in the simulator's pictures.
cv::Vec3b label_colour(std::uint8_t label) {
  switch (label) {
    case kLabelPixelOutside:
      return {40, 40, 40};
    case 1:
      return {60, 160, 230};
    case 2:
      return {90, 200, 90};
    case 3:
      return {230, 230, 230};
    case kLabelPixelUnknown:
      return {0, 0, 0};
    default:
      return {200, 100, 200};
  }
}

// Labels in colour; unknown inside the sector hatched so it reads apart from "outside".
void draw_labels(const LabelImage& labels, const ImageU8& sector, cv::Mat roi) {
  for (int j = 0; j < labels.height; ++j)
    for (int i = 0; i < labels.width; ++i) {
      const std::uint8_t l = labels.at(i, j);
      cv::Vec3b c = label_colour(l);
      if (l == kLabelPixelUnknown && sector.at(i, j))
        c = ((i + j) / 4) % 2 ? cv::Vec3b(120, 40, 160) : cv::Vec3b(60, 20, 80);
      roi.at<cv::Vec3b>(j, i) = c;
    }
}

cv::Mat panels(const simulator::SimulatedFrame& frame,
               const segmentation::Segmentation& segmentation, const ImageU8& sector,
               const LabeledSlice& slice, const acquisition::Probe& probe) {
  const int w = frame.bmode.width, h = frame.bmode.height;
  cv::Mat out(h, 3 * w + 2 * kGapPx, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const std::uint8_t g = frame.bmode.at(i, j);
      out.at<cv::Vec3b>(j, i) = cv::Vec3b(g, g, g);
    }
  draw_labels(frame.truth, sector, out(cv::Rect(w + kGapPx, 0, w, h)));
  cv::Mat seg_roi = out(cv::Rect(2 * (w + kGapPx), 0, w, h));
  draw_labels(segmentation.labels, sector, seg_roi);
  // The slice's polygons (plane coordinates are probe mm here), outlines and holes in white.
  for (const Region& region : slice.regions) {
    std::vector<std::vector<cv::Point>> rings;
    for (const Ring2* ring : [&] {
           std::vector<const Ring2*> all{&region.outer};
           for (const Ring2& hole : region.holes) all.push_back(&hole);
           return all;
         }()) {
      std::vector<cv::Point> points;
      for (const Vec2& p : *ring) {
        const Vec2 px = probe.mm_to_pixel(p);
        points.emplace_back(static_cast<int>(std::lround(px.x())),
                            static_cast<int>(std::lround(px.y())));
      }
      rings.push_back(points);
    }
    cv::polylines(seg_roi, rings, true, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  const std::filesystem::path source = SONOSHAPE_SOURCE_DIR;
  const std::filesystem::path out_dir = argc > 1 ? argv[1] : source / "docs" / "images";
  std::filesystem::create_directories(out_dir);
  struct Shot {
    const char* file;
    acquisition::ProbeGeometry probe;
    double size_mm, standoff_mm, z_fraction, x_mm;
  };
  // The pictured planes of docs/simulator.md.
  const Shot shots[] = {
      {"seg_convex.png", acquisition::convex_probe_geometry(512, 512), 120.0, 12.0, 0.45, 0.0},
      {"seg_linear.png", acquisition::linear_probe_geometry(512, 512), 60.0, 4.0, 0.45, -6.0},
  };
  for (const Shot& shot : shots) {
    auto phantom = simulator::make_default_phantom(source / "data" / "models", shot.size_mm);
    if (!phantom) {
      std::cerr << "error: " << phantom.message() << '\n';
      return 1;
    }
    const Box3 box = phantom->bounds();
    const acquisition::Probe probe(shot.probe);
    const simulator::BModeSimulator simulator(*phantom, probe);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Vec3(shot.x_mm, box.min.y() - shot.standoff_mm,
                              box.min.z() + shot.z_fraction * box.size().z());

    // A short sweep around the plane gives the header models `segment` would use.
    simulator::TrajectoryOptions motion;
    motion.T_reference_probe_centre = pose;
    motion.duration_s = 0.75;
    motion.sweep_length_mm = 0.5 * box.size().z();
    const auto acquisition =
        simulator::acquire(simulator::Trajectory(motion), simulator::TrackerOptions{}, 16, 20.0);
    const simulator::SimulatedSweep sweep = simulator::simulate_sweep(simulator, acquisition, 3);
    const auto setup = segmentation::prepare_sweep(
        sweep.bmode, "docs.igs.mha", std::optional<segmentation::SegmentationConfig>{},
        std::optional<Eigen::Matrix4d>{});
    if (!setup) {
      std::cerr << "error: " << setup.message() << '\n';
      return 1;
    }

    const simulator::SimulatedFrame frame = simulator.render(pose, 7);
    const segmentation::Segmentation segmentation =
        segmentation::segment_frame(frame.bmode, setup->geometry, setup->config);
    // Plane coordinates = probe mm (identity pose), so the polygons map back by the probe.
    const segmentation::ImagePlane plane =
        segmentation::image_plane(probe.T_probe_image().matrix(), Vec3::Zero());
    const auto slice =
        segmentation::make_slice(segmentation.labels, setup->geometry.sector,
                                 setup->geometry.sector_px, plane, setup->config.simplify_mm);
    if (!slice) {
      std::cerr << "error: " << slice.message() << '\n';
      return 1;
    }
    const auto path = out_dir / shot.file;
    const cv::Mat picture = panels(frame, segmentation, setup->geometry.sector, *slice, probe);
    if (const Status written = write_png(path, PngPixels::kBgr, picture.cols, picture.rows,
                                         picture.data, static_cast<std::ptrdiff_t>(picture.step));
        !written) {
      std::cerr << "error: " << written.message() << '\n';
      return 1;
    }
    std::size_t vertices = 0;
    for (const Region& r : slice->regions) {
      vertices += r.outer.size();
      for (const Ring2& hole : r.holes) vertices += hole.size();
    }
    std::cout << "wrote " << path.string() << " (" << slice->regions.size() << " regions, "
              << vertices << " vertices)\n";
  }
  // The real PLUS sweep (spine phantom, no labels known): B-mode and the two-class result.
  const auto plus_dir = source / "data" / "plus";
  const auto plus = acquisition::read_sequence_file(plus_dir / "SpinePhantomFreehand.igs.mha");
  if (!plus) {
    std::cerr << "error: " << plus.message() << '\n';
    return 1;
  }
  const auto setup = segmentation::prepare_sweep(
      *plus, plus_dir / "SpinePhantomFreehand.igs.mha", std::optional<std::filesystem::path>{},
      plus_dir / "PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml");
  if (!setup) {
    std::cerr << "error: " << setup.message() << '\n';
    return 1;
  }
  const GreyImage& image = plus->image(10);
  const segmentation::Segmentation segmentation =
      segmentation::segment_frame(image, setup->geometry, setup->config);
  const int w = image.width, h = image.height;
  cv::Mat out(h, 2 * w + kGapPx, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) out.at<cv::Vec3b>(j, i) = cv::Vec3b::all(image.at(i, j));
  draw_labels(segmentation.labels, setup->geometry.sector, out(cv::Rect(w + kGapPx, 0, w, h)));
  const auto path = out_dir / "seg_plus.png";
  if (const Status written = write_png(path, PngPixels::kBgr, out.cols, out.rows, out.data,
                                       static_cast<std::ptrdiff_t>(out.step));
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  std::cout << "wrote " << path.string() << '\n';
  return 0;
}
