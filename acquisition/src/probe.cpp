#include "sonoshape/acquisition/probe.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "sonoshape/core/errors.hpp"

namespace sonoshape::acquisition {

ProbeType parse_probe_type(const std::string& name) {
  if (name == "linear") return ProbeType::kLinear;
  if (name == "convex" || name == "curvilinear") return ProbeType::kConvex;
  throw std::invalid_argument("unknown probe type '" + name + "' (use linear or convex)");
}

std::string to_string(ProbeType type) { return type == ProbeType::kLinear ? "linear" : "convex"; }

ProbeGeometry convex_probe_geometry(int width_px, int height_px) {
  ProbeGeometry g;
  g.type = ProbeType::kConvex;
  g.depth_mm = 120.0;
  g.fan_angle_deg = 60.0;
  g.radius_mm = 40.0;
  g.width_px = width_px;
  g.height_px = height_px;
  g.frequency_mhz = 3.5;
  return g;
}

ProbeGeometry linear_probe_geometry(int width_px, int height_px) {
  ProbeGeometry g;
  g.type = ProbeType::kLinear;
  g.depth_mm = 50.0;
  g.width_mm = 40.0;
  g.width_px = width_px;
  g.height_px = height_px;
  g.frequency_mhz = 7.5;
  return g;
}

Probe::Probe(const ProbeGeometry& geometry) : geometry_(geometry) {
  const ProbeGeometry& g = geometry_;
  if (g.width_px < 2 || g.height_px < 2 || !(g.depth_mm > 0.0) || !(g.frequency_mhz > 0.0))
    throw GeometryError("probe: image size must be at least 2x2 and depth, frequency positive");
  double x_extent = 0.0, y_top = 0.0, y_bottom = g.depth_mm;
  if (g.type == ProbeType::kLinear) {
    if (!(g.width_mm > 0.0)) throw GeometryError("linear probe: width_mm must be positive");
    x_extent = g.width_mm;
  } else {
    if (!(g.fan_angle_deg > 0.0 && g.fan_angle_deg < 180.0) || !(g.radius_mm > 0.0))
      throw GeometryError("convex probe: fan angle must be in (0, 180) deg, radius positive");
    half_angle_rad_ = 0.5 * g.fan_angle_deg * std::numbers::pi / 180.0;
    x_extent = 2.0 * (g.radius_mm + g.depth_mm) * std::sin(half_angle_rad_);
    y_top = g.radius_mm * std::cos(half_angle_rad_) - g.radius_mm;  // the face's ends
  }
  spacing_mm_ = std::max(x_extent / (g.width_px - 1), (y_bottom - y_top) / (g.height_px - 1));
  top_mm_ = y_top;
}

Eigen::Affine3d Probe::T_probe_image() const {
  Eigen::Affine3d T = Eigen::Affine3d::Identity();
  T.linear() = spacing_mm_ * Eigen::Matrix3d::Identity();
  T.translation() = Vec3(-0.5 * (geometry_.width_px - 1) * spacing_mm_, top_mm_, 0.0);
  return T;
}

Vec2 Probe::pixel_to_mm(double i, double j) const {
  return Vec2((i - 0.5 * (geometry_.width_px - 1)) * spacing_mm_, top_mm_ + j * spacing_mm_);
}

Vec2 Probe::mm_to_pixel(const Vec2& xy_mm) const {
  return Vec2(xy_mm.x() / spacing_mm_ + 0.5 * (geometry_.width_px - 1),
              (xy_mm.y() - top_mm_) / spacing_mm_);
}

bool Probe::in_sector(const Vec2& p) const {
  const ProbeGeometry& g = geometry_;
  if (g.type == ProbeType::kLinear)
    return std::abs(p.x()) <= 0.5 * g.width_mm && p.y() >= 0.0 && p.y() <= g.depth_mm;
  const Vec2 from_centre(p.x(), p.y() + g.radius_mm);
  const double r = from_centre.norm();
  return r >= g.radius_mm && r <= g.radius_mm + g.depth_mm &&
         std::abs(std::atan2(from_centre.x(), from_centre.y())) <= half_angle_rad_;
}

ImageU8 Probe::sector_mask() const {
  ImageU8 mask(geometry_.width_px, geometry_.height_px, 0);
  for (int j = 0; j < mask.height; ++j)
    for (int i = 0; i < mask.width; ++i)
      if (in_sector(pixel_to_mm(i, j))) mask.at(i, j) = 255;
  return mask;
}

Ring2 Probe::sector_ring_mm(int arc_points) const {
  const ProbeGeometry& g = geometry_;
  if (g.type == ProbeType::kLinear) {
    const double h = 0.5 * g.width_mm;
    return {Vec2(-h, 0.0), Vec2(h, 0.0), Vec2(h, g.depth_mm), Vec2(-h, g.depth_mm)};
  }
  arc_points = std::max(arc_points, 2);
  Ring2 ring;
  const Vec2 centre(0.0, -g.radius_mm);
  auto at = [&](double radius, double angle) {
    return Vec2(centre + radius * Vec2(std::sin(angle), std::cos(angle)));
  };
  // Near arc left to right, far arc back; the orientation is fixed up below.
  for (int k = 0; k < arc_points; ++k)
    ring.push_back(at(g.radius_mm, half_angle_rad_ * (2.0 * k / (arc_points - 1) - 1.0)));
  for (int k = arc_points - 1; k >= 0; --k)
    ring.push_back(
        at(g.radius_mm + g.depth_mm, half_angle_rad_ * (2.0 * k / (arc_points - 1) - 1.0)));
  if (signed_area(ring) < 0.0) std::reverse(ring.begin(), ring.end());
  return ring;
}

Vec2 Probe::beam_to_mm(double b, double s) const {
  const ProbeGeometry& g = geometry_;
  const double depth = (s + 0.5) * axial_step_mm();
  const double fraction = (b + 0.5) / g.width_px;  // 0 .. 1 across the array
  if (g.type == ProbeType::kLinear) return Vec2((fraction - 0.5) * g.width_mm, depth);
  const double angle = (2.0 * fraction - 1.0) * half_angle_rad_;
  const double r = g.radius_mm + depth;
  return Vec2(r * std::sin(angle), r * std::cos(angle) - g.radius_mm);
}

Vec2 Probe::mm_to_beam(const Vec2& p) const {
  const ProbeGeometry& g = geometry_;
  double fraction = 0.0, depth = 0.0;
  if (g.type == ProbeType::kLinear) {
    fraction = p.x() / g.width_mm + 0.5;
    depth = p.y();
  } else {
    const Vec2 from_centre(p.x(), p.y() + g.radius_mm);
    fraction = 0.5 * (std::atan2(from_centre.x(), from_centre.y()) / half_angle_rad_ + 1.0);
    depth = from_centre.norm() - g.radius_mm;
  }
  return Vec2(fraction * g.width_px - 0.5, depth / axial_step_mm() - 0.5);
}

double Probe::lateral_step_mm(double s) const {
  const ProbeGeometry& g = geometry_;
  if (g.type == ProbeType::kLinear) return g.width_mm / g.width_px;
  return (g.radius_mm + sample_depth_mm(s)) * 2.0 * half_angle_rad_ / g.width_px;
}

namespace {

std::string number(double value) {
  std::array<char, 32> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  return ec == std::errc() ? std::string(buffer.data(), end) : "nan";
}

}  // namespace

FieldList probe_fields(const Probe& probe) {
  const ProbeGeometry& g = probe.geometry();
  FieldList fields;
  fields.emplace_back("SonoshapeProbeType", to_string(g.type));
  fields.emplace_back("SonoshapeProbeDepthMm", number(g.depth_mm));
  fields.emplace_back("SonoshapeProbeWidthMm", number(g.width_mm));
  fields.emplace_back("SonoshapeProbeFanAngleDeg", number(g.fan_angle_deg));
  fields.emplace_back("SonoshapeProbeRadiusMm", number(g.radius_mm));
  fields.emplace_back("SonoshapeProbeFrequencyMhz", number(g.frequency_mhz));
  fields.emplace_back("SonoshapeImageSizePx",
                      std::to_string(g.width_px) + " " + std::to_string(g.height_px));
  fields.emplace_back("SonoshapePixelSpacingMm", number(probe.spacing_mm()));
  return fields;
}

Result<Probe> probe_from_fields(const FieldList& fields) {
  auto get = [&](const char* key) -> Result<double> {
    const auto text = find_field(fields, key);
    if (!text)
      return Status::error(std::string("sequence header has no ") + key +
                           " field: it was not written by `sonoshape simulate`; give the probe "
                           "geometry another way");
    double value = 0.0;
    const auto [end, ec] = std::from_chars(text->data(), text->data() + text->size(), value);
    if (ec != std::errc() || end != text->data() + text->size())
      return Status::error(std::string("sequence header field ") + key + " = '" + *text +
                           "' is not a number");
    return value;
  };
  ProbeGeometry g;
  const auto type = find_field(fields, "SonoshapeProbeType");
  if (!type || (*type != "linear" && *type != "convex"))
    return Status::error(
        "sequence header field SonoshapeProbeType is missing or not "
        "linear/convex");
  g.type = parse_probe_type(*type);
  for (auto [key, target] : {std::pair{"SonoshapeProbeDepthMm", &g.depth_mm},
                             std::pair{"SonoshapeProbeWidthMm", &g.width_mm},
                             std::pair{"SonoshapeProbeFanAngleDeg", &g.fan_angle_deg},
                             std::pair{"SonoshapeProbeRadiusMm", &g.radius_mm},
                             std::pair{"SonoshapeProbeFrequencyMhz", &g.frequency_mhz}}) {
    const auto value = get(key);
    if (!value) return value.status();
    *target = *value;
  }
  const auto size = find_field(fields, "SonoshapeImageSizePx");
  std::istringstream in(size.value_or(""));
  if (!(in >> g.width_px >> g.height_px))
    return Status::error("sequence header field SonoshapeImageSizePx is missing or not 'W H'");
  try {
    return Probe(g);
  } catch (const GeometryError& e) {
    return Status::error(std::string("sequence header describes an invalid probe: ") + e.what());
  }
}

}  // namespace sonoshape::acquisition
