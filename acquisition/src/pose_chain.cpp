#include "sonoshape/acquisition/pose_chain.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <deque>
#include <map>
#include <set>

#include "sequence_text.hpp"

namespace sonoshape::acquisition {
namespace {

using detail::fail;
using detail::kTransformSuffix;

// Default reconstruction frames, in order: PLUS's Reference, then the tracker itself, then a
// TRUS stepper's template (where the phantom or the needle grid is) and its home position.
constexpr std::string_view kDefaultTargets[] = {"Reference", "Tracker", "Template", "StepperHome"};
constexpr std::string_view kProbeNames[] = {"Probe", "Tool"};

std::string strip_suffix(std::string_view name) {
  if (name.size() > kTransformSuffix.size() &&
      name.substr(name.size() - kTransformSuffix.size()) == kTransformSuffix)
    name.remove_suffix(kTransformSuffix.size());
  return std::string(name);
}

bool image_side(const std::string& frame) { return frame == "Image" || frame == "CroppedImage"; }

struct Edge {
  std::string from, to;  // as stored: maps from into to
  PoseChainStep step;    // inverse = false
};

std::vector<Edge> graph_edges(const SequenceFile& file, const PlusConfig& fixed) {
  std::vector<Edge> edges;
  std::set<std::pair<std::string, std::string>> seen;
  auto add = [&](const std::string& from, const std::string& to, PoseChainStep step) {
    if (image_side(from) || image_side(to) || from == to) return;
    // One edge per pair of frames: the recording's own measurement wins over a fixed copy.
    if (seen.count({from, to}) || seen.count({to, from})) return;
    seen.insert({from, to});
    edges.push_back({from, to, std::move(step)});
  };
  for (const std::string& name : file.transform_names())
    if (const auto split = split_transform_name(name))
      add(split->first, split->second, {name, true, false, Eigen::Matrix4d::Identity()});
  for (const PlusTransform& t : fixed.transforms)
    add(t.from, t.to, {t.from + "To" + t.to, false, false, t.matrix});
  return edges;
}

// Shortest path (fewest transforms) from `from` to `to`; none when they are not connected.
std::optional<std::vector<PoseChainStep>> find_path(const std::vector<Edge>& edges,
                                                    const std::string& from,
                                                    const std::string& to) {
  std::map<std::string, std::pair<std::string, PoseChainStep>> came_from;
  std::deque<std::string> queue{from};
  std::set<std::string> visited{from};
  while (!queue.empty()) {
    const std::string node = queue.front();
    queue.pop_front();
    if (node == to) break;
    for (const Edge& e : edges) {
      for (const bool inverse : {false, true}) {
        const std::string& a = inverse ? e.to : e.from;
        const std::string& b = inverse ? e.from : e.to;
        if (a != node || visited.count(b)) continue;
        visited.insert(b);
        PoseChainStep step = e.step;
        step.inverse = inverse;
        came_from[b] = {node, std::move(step)};
        queue.push_back(b);
      }
    }
  }
  if (!visited.count(to)) return std::nullopt;
  std::vector<PoseChainStep> path;
  for (std::string node = to; node != from;) {
    const auto& [previous, step] = came_from.at(node);
    path.push_back(step);
    node = previous;
  }
  std::reverse(path.begin(), path.end());
  return path;
}

std::set<std::string> reachable(const std::vector<Edge>& edges, const std::string& from) {
  std::set<std::string> nodes{from};
  for (bool grew = true; grew;) {
    grew = false;
    for (const Edge& e : edges)
      for (const auto& [a, b] : {std::pair{e.from, e.to}, std::pair{e.to, e.from}})
        if (nodes.count(a) && nodes.insert(b).second) grew = true;
  }
  nodes.erase(from);
  return nodes;
}

std::string join(const std::vector<std::string>& items) {
  std::string text;
  for (const std::string& s : items) text += (text.empty() ? "" : ", ") + s;
  return text.empty() ? "none" : text;
}

std::string edge_list(const std::vector<Edge>& edges) {
  std::vector<std::string> names;
  for (const Edge& e : edges)
    names.push_back(e.step.name + (e.step.per_frame ? "" : " (device set)"));
  return join(names);
}

bool is_pure_translation(const Eigen::Matrix4d& m) {
  return (m.block<3, 3>(0, 0) - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-9 &&
         (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() < 1e-9 &&
         std::abs(m(2, 3)) < 1e-9;
}

}  // namespace

std::optional<std::pair<std::string, std::string>> split_transform_name(std::string_view name) {
  const std::string stripped = strip_suffix(name);
  std::optional<std::pair<std::string, std::string>> found;
  for (std::size_t i = 1; i + 2 < stripped.size(); ++i) {
    if (stripped.compare(i, 2, "To") != 0) continue;
    if (!std::isupper(static_cast<unsigned char>(stripped[i + 2]))) continue;
    if (!std::isupper(static_cast<unsigned char>(stripped[0]))) return std::nullopt;
    if (found) return std::nullopt;  // ambiguous: "AToBToC"
    found = std::pair{stripped.substr(0, i), stripped.substr(i + 2)};
  }
  return found;
}

std::string PoseChain::describe() const {
  std::string text = from + "To" + to + " = ";
  if (steps.empty()) return text + "identity";
  bool any_fixed = false;
  for (std::size_t i = steps.size(); i-- > 0;) {
    const PoseChainStep& s = steps[i];
    text +=
        s.name + (s.inverse ? "^-1" : "") + (s.per_frame ? "" : "[device set]") + (i ? " * " : "");
    any_fixed = any_fixed || !s.per_frame;
  }
  return text + (any_fixed ? " (per frame and fixed)" : " (per frame)");
}

std::vector<std::string> PoseChain::per_frame_names() const {
  std::vector<std::string> names;
  for (const PoseChainStep& s : steps)
    if (s.per_frame) names.push_back(s.name);
  return names;
}

std::optional<Eigen::Matrix4d> PoseChain::pose(const SequenceFile& file, std::size_t k) const {
  Eigen::Matrix4d T_to_from = Eigen::Matrix4d::Identity();
  for (const PoseChainStep& s : steps) {
    Eigen::Matrix4d m = s.matrix;
    if (s.per_frame) {
      if (file.transform_status(s.name, k) != TrackingStatus::kValid) return std::nullopt;
      const auto read = file.transform(s.name, k);
      if (!read) return std::nullopt;
      m = *read;
    }
    if (s.inverse) {
      Eigen::Matrix4d inverse;
      bool invertible = false;
      m.computeInverseWithCheck(inverse, invertible);
      if (!invertible) return std::nullopt;
      m = inverse;
    }
    T_to_from = m * T_to_from;
  }
  if (!T_to_from.allFinite()) return std::nullopt;
  return T_to_from;
}

PoseChain legacy_pose_chain(const SequenceFile& file) {
  PoseChain chain;
  chain.chosen_by = "default";
  chain.steps.push_back({"ProbeToTracker", true, false, Eigen::Matrix4d::Identity()});
  const auto names = file.transform_names();
  if (std::find(names.begin(), names.end(), "ReferenceToTracker") == names.end()) {
    chain.to = "Tracker";
  } else {
    chain.steps.push_back({"ReferenceToTracker", true, true, Eigen::Matrix4d::Identity()});
  }
  return chain;
}

Result<PoseChain> find_pose_chain(const SequenceFile& file, const std::filesystem::path& path,
                                  std::string_view requested, const PlusConfig& fixed) {
  const std::vector<Edge> edges = graph_edges(file, fixed);
  auto chain_of = [&](const std::string& from, const std::string& to,
                      const std::string& chosen_by) -> std::optional<PoseChain> {
    const auto steps = find_path(edges, from, to);
    if (!steps || (steps->empty() && from != to)) return std::nullopt;
    PoseChain chain;
    chain.from = from;
    chain.to = to;
    chain.steps = *steps;
    chain.chosen_by = chosen_by;
    return chain;
  };
  auto no_chain = [&](const std::string& name, const std::string& by) -> Status {
    const auto split = split_transform_name(name);
    std::vector<std::string> from_there;
    if (split)
      for (const std::string& n : reachable(edges, split->first)) from_there.push_back(n);
    return fail(path,
                by + " asks for the pose " + name + ", but no chain of transforms joins " +
                    (split ? split->first + " to " + split->second
                           : std::string("its frames (it is not '<From>To<To>')")) +
                    " (transforms: " + edge_list(edges) + "; frames reachable from " +
                    (split ? split->first : std::string("it")) + ": " + join(from_there) + ")",
                "name a pose the file's transforms reach with --pose-transform FROMToTO (e.g. "
                "ProbeToReference), or give the device set whose <CoordinateDefinitions> holds "
                "the missing transform");
  };
  auto named = [&](std::string_view text, const std::string& by) -> Result<PoseChain> {
    const std::string name = strip_suffix(text);
    const auto split = split_transform_name(name);
    if (!split)
      return fail(path, by + " '" + std::string(text) + "' is not a transform name",
                  "write it as <From>To<To>, e.g. ProbeToReference or ToolToTracker");
    // PLUS's placeholder IdentityToIdentity (timing test data) is no pose.
    if (split->first == split->second)
      return fail(path, by + " '" + std::string(text) + "' maps a frame onto itself, no pose",
                  "name the probe's transform with --pose-transform FROMToTO");
    if (auto chain = chain_of(split->first, split->second, by)) return *chain;
    return no_chain(name, by);
  };
  if (!requested.empty()) return named(requested, "--pose-transform");
  if (const auto header = file.field("DefaultFrameTransformName");
      header && !detail::trim(*header).empty())
    return named(detail::trim(*header),
                 "the header's DefaultFrameTransformName = " + std::string(detail::trim(*header)));
  for (const std::string_view probe : kProbeNames)
    for (const std::string_view target : kDefaultTargets)
      if (auto chain = chain_of(std::string(probe), std::string(target), "default")) return *chain;
  std::vector<std::string> from_probe;
  for (const std::string& n : reachable(edges, "Probe")) from_probe.push_back(n);
  return fail(path,
              "no chain of transforms gives the probe's pose: none joins Probe (or Tool) to "
              "Reference, Tracker, Template or StepperHome (transforms: " +
                  edge_list(edges) + "; frames reachable from Probe: " + join(from_probe) + ")",
              "a tracked sweep needs the probe's pose per frame (PLUS Seq_FrameNNNN_"
              "ProbeToTrackerTransform); if it is there under another name, give it with "
              "--pose-transform FROMToTO");
}

Result<std::optional<Eigen::Matrix4d>> image_to_cropped_image(const SequenceFile& file,
                                                              const std::filesystem::path& path) {
  constexpr std::string_view kName = "ImageToCroppedImage";
  const auto names = file.transform_names();
  if (std::find(names.begin(), names.end(), kName) == names.end())
    return std::optional<Eigen::Matrix4d>();
  std::optional<Eigen::Matrix4d> first;
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const std::string where = "frame " + std::to_string(k) + ": ImageToCroppedImageTransform";
    const auto m = file.transform(kName, k);
    if (!m)
      return fail(path, where + " is missing or not 16 numbers",
                  "a cropped recording gives every frame its crop; write it for each frame");
    if (!is_pure_translation(*m))
      return fail(path, where + " is not a pixel shift in the image plane",
                  "PLUS writes a crop as a translation (1 0 0 -x0 0 1 0 -y0 0 0 1 0 0 0 0 1); "
                  "fix the matrix");
    if (first && (*m - *first).cwiseAbs().maxCoeff() > 1e-9)
      return fail(path, where + " differs from frame 0's (the crop moves)",
                  "sonoshape takes one crop for the whole recording; split the file where the "
                  "crop changes");
    if (!first) first = *m;
  }
  return first;
}

Result<bool> reorient_to_mf(SequenceFile& file, const std::filesystem::path& path) {
  const auto field = file.field("UltrasoundImageOrientation");
  if (!field) return false;
  const std::string code(detail::trim(*field));
  const bool plus_2d =
      (code.size() == 2 || (code.size() == 3 && (code[2] == 'A' || code[2] == 'D'))) &&
      (code[0] == 'M' || code[0] == 'U') && (code[1] == 'F' || code[1] == 'N');
  if (!plus_2d)
    return fail(path, "UltrasoundImageOrientation = '" + code + "' is not a 2D image orientation",
                "B-mode frames are MF, MN, UF or UN (PLUS; FM/NM are RF line data, which "
                "sonoshape does not reconstruct); write the code the frames are in");
  const bool flip_columns = code[0] == 'U';
  const bool flip_rows = code[1] == 'N';
  if (!flip_columns && !flip_rows) return false;
  const int w = file.width(), h = file.height();
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    GreyImage& image = file.image(k);
    std::vector<std::uint8_t> flipped(image.pixels.size());
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        const int si = flip_columns ? w - 1 - i : i;
        const int sj = flip_rows ? h - 1 - j : j;
        flipped[static_cast<std::size_t>(j) * w + i] =
            image.pixels[static_cast<std::size_t>(sj) * w + si];
      }
    image.pixels = std::move(flipped);
  }
  file.set_field("UltrasoundImageOrientation", "MF" + code.substr(2));
  return true;
}

std::optional<double> fill_missing_timestamps(SequenceFile& file) {
  for (std::size_t k = 0; k < file.frame_count(); ++k)
    if (file.frame_field(k, "Timestamp")) return std::nullopt;
  double rate_hz = 10.0;
  if (const auto text = file.field("AcquisitionFrameRate"))
    if (const auto rate = detail::parse_number<double>(*text); rate && *rate > 0.0) rate_hz = *rate;
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    char text[32];
    std::snprintf(text, sizeof text, "%.6f", static_cast<double>(k) / rate_hz);
    file.set_frame_field(k, "Timestamp", text);
  }
  return rate_hz;
}

}  // namespace sonoshape::acquisition
