// Mesh-stream messages (docs/formats/mesh-stream.md): encoding and the validating decoder.
#include "sonoshape/publish/mesh_stream.hpp"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <type_traits>

#include "sonoshape/core/errors.hpp"
#include "sonoshape/core/slice_io.hpp"

namespace sonoshape::publish {
namespace {

using nlohmann::json;
using nlohmann::ordered_json;

// Bytes of one vertex (3 float32) and of one triangle (3 uint32) on the wire.
constexpr std::size_t kVertexBytes = 12;
constexpr std::size_t kTriangleBytes = 12;
// Positions may differ from the header's bounds by float32 rounding: about 6e-8 of their size.
constexpr double kBoundsRelTol = 1e-6;

// ---------------------------------------------------------------------------------------------
// Little-endian binary frames, whatever the host.

std::uint32_t to_little(std::uint32_t bits) {
  if constexpr (std::endian::native == std::endian::big)
    bits =
        ((bits & 0xffu) << 24) | ((bits & 0xff00u) << 8) | ((bits >> 8) & 0xff00u) | (bits >> 24);
  return bits;
}

void put_u32(char* out, std::uint32_t value) {
  const std::uint32_t bits = to_little(value);
  std::memcpy(out, &bits, sizeof bits);
}

std::uint32_t get_u32(const char* in) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, in, sizeof bits);
  return to_little(bits);  // the swap is its own inverse
}

void put_f32(char* out, float value) { put_u32(out, std::bit_cast<std::uint32_t>(value)); }
float get_f32(const char* in) { return std::bit_cast<float>(get_u32(in)); }

// N*3 float32; false when a value is not finite as float32 (NaN, or beyond its range). `box`,
// when given, receives the box of the float32 values (left alone for no points).
bool vec3s_to_f32(const std::vector<Vec3>& points, std::string& out, Box3* box = nullptr) {
  out.resize(points.size() * kVertexBytes);
  char* p = out.data();
  for (std::size_t i = 0; i < points.size(); ++i) {
    Vec3 sent;
    for (int k = 0; k < 3; ++k, p += 4) {
      const float f = static_cast<float>(points[i][k]);
      if (!std::isfinite(f)) return false;
      put_f32(p, f);
      sent[k] = f;
    }
    if (box) {
      box->min = i ? box->min.cwiseMin(sent) : sent;
      box->max = i ? box->max.cwiseMax(sent) : sent;
    }
  }
  return true;
}

std::vector<Vec3> f32_to_vec3s(const std::string& bytes) {
  std::vector<Vec3> points(bytes.size() / kVertexBytes);
  const char* p = bytes.data();
  for (Vec3& v : points)
    for (int k = 0; k < 3; ++k, p += 4) v[k] = get_f32(p);
  return points;
}

// ---------------------------------------------------------------------------------------------
// Encoding

ordered_json vec3_json(const Vec3& v) { return ordered_json::array({v.x(), v.y(), v.z()}); }

Result<Frames> encode_mesh(const StreamMessage& message, const MeshUpdate& update) {
  const std::string where = "mesh." + std::to_string(update.label);
  const TriangleMesh& mesh = update.mesh;
  constexpr std::size_t kMaxCount = std::numeric_limits<std::uint32_t>::max();
  if (update.label < 1)
    return Status::error("cannot encode a mesh of label " + std::to_string(update.label) +
                         ": material ids start at 1");
  if (mesh.vertices.size() > kMaxCount || mesh.triangles.size() > kMaxCount)
    return Status::error("cannot encode " + where + ": more than 2^32-1 vertices or triangles");
  if (!std::isfinite(update.timestamp_s))
    return Status::error("cannot encode " + where + ": timestamp_s is not finite");
  const auto vertex_count = static_cast<std::uint32_t>(mesh.vertices.size());

  Frames frames(4);
  frames[0] = where;
  // The box of what is sent (float32), so that it holds every received position exactly.
  Box3 box;
  if (!vec3s_to_f32(mesh.vertices, frames[2], &box))
    return Status::error("cannot encode " + where +
                         ": a vertex position is NaN, infinite or beyond float32 range");
  frames[3].resize(mesh.triangles.size() * kTriangleBytes);
  char* p = frames[3].data();
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (std::uint32_t index : mesh.triangles[t]) {
      if (index >= vertex_count)
        return Status::error("cannot encode " + where + ": triangle " + std::to_string(t) +
                             " uses vertex " + std::to_string(index) + " of " +
                             std::to_string(vertex_count));
      put_u32(p, index);
      p += 4;
    }
  if (update.normals) {
    if (update.normals->size() != mesh.vertices.size())
      return Status::error("cannot encode " + where + ": " +
                           std::to_string(update.normals->size()) + " normals for " +
                           std::to_string(vertex_count) + " vertices; give one per vertex");
    frames.emplace_back();
    if (!vec3s_to_f32(*update.normals, frames[4]))
      return Status::error("cannot encode " + where + ": a normal is NaN or infinite");
  }

  ordered_json header;
  header["v"] = kMeshStreamVersion;
  header["seq"] = message.seq;
  header["scan"] = message.scan;
  header["label"] = update.label;
  header["name"] = update.name;
  header["units"] = update.units;
  header["frame"] = update.frame;
  header["timestamp_s"] = update.timestamp_s;
  header["slices"] = update.slices;
  header["vertex_count"] = mesh.vertices.size();
  header["triangle_count"] = mesh.triangles.size();
  if (mesh.vertices.empty()) {
    header["bounds"] = nullptr;  // nothing to bound (a vanished material)
  } else {
    header["bounds"] = {{"min", vec3_json(box.min)}, {"max", vec3_json(box.max)}};
  }
  if (update.normals) header["normals"] = true;
  frames[1] = header.dump();
  return frames;
}

ordered_json plane_json(const PlaneFrame& plane) {
  ordered_json j;
  j["origin"] = vec3_json(plane.origin_mm);
  j["u"] = vec3_json(plane.u);
  j["v"] = vec3_json(plane.v);
  return j;
}

Result<Frames> encode_slice(const StreamMessage& message, const SliceUpdate& update) {
  Result<std::string> object = write_slice_json(update.slice);
  if (!object)
    return Status::error("cannot encode slice " + std::to_string(update.index) + ": " +
                         object.message());
  // The message's own keys first, so that a reader sees them first; the slice's plane under
  // "plane", so that "v" is the version as in every other header; then the rest of the slice
  // object (fov, regions, timestamp) as slices.md writes it.
  ordered_json header;
  header["v"] = kMeshStreamVersion;
  header["seq"] = message.seq;
  header["scan"] = message.scan;
  header["index"] = update.index;
  header["plane"] = plane_json({update.slice.origin_mm, update.slice.u, update.slice.v});
  ordered_json slice = ordered_json::parse(*object);
  for (auto& [key, value] : slice.items())
    if (key != "origin" && key != "u" && key != "v") header[key] = std::move(value);
  return Frames{std::string(kSliceTopic), header.dump()};
}

// Whether `plane` has unit, orthogonal directions (to 1e-6, as slices.md asks of a slice).
bool orthonormal(const PlaneFrame& plane) {
  constexpr double kTol = 1e-6;
  return plane.origin_mm.allFinite() && std::abs(plane.u.norm() - 1.0) <= kTol &&
         std::abs(plane.v.norm() - 1.0) <= kTol && std::abs(plane.u.dot(plane.v)) <= kTol;
}

Result<Frames> encode_frame(const StreamMessage& message, const FrameImage& frame) {
  const std::string where = "cannot encode frame " + std::to_string(frame.index) + ": ";
  const GreyImage& image = frame.image;
  if (image.width < 1 || image.height < 1 || image.width > kMaxFrameImageSide ||
      image.height > kMaxFrameImageSide)
    return Status::error(where + "picture of " + std::to_string(image.width) + " x " +
                         std::to_string(image.height) + " px; give 1 to " +
                         std::to_string(kMaxFrameImageSide) + " px a side (downsample it)");
  if (image.pixels.size() != static_cast<std::size_t>(image.width) * image.height)
    return Status::error(where + "the picture holds " + std::to_string(image.pixels.size()) +
                         " pixels, not width * height");
  if (!std::isfinite(frame.timestamp_s) || !frame.size_mm.allFinite() ||
      (frame.size_mm.array() <= 0.0).any())
    return Status::error(where + "timestamp_s and size_mm must be finite, size_mm positive");
  if (!orthonormal(frame.plane))
    return Status::error(where + "the plane's u and v must be unit and orthogonal");
  ordered_json header;
  header["v"] = kMeshStreamVersion;
  header["seq"] = message.seq;
  header["scan"] = message.scan;
  header["index"] = frame.index;
  header["timestamp_s"] = frame.timestamp_s;
  header["format"] = "gray8";
  header["width"] = image.width;
  header["height"] = image.height;
  header["plane"] = plane_json(frame.plane);
  header["size_mm"] = ordered_json::array({frame.size_mm.x(), frame.size_mm.y()});
  return Frames{std::string(kFrameTopic), header.dump(),
                std::string(image.pixels.begin(), image.pixels.end())};
}

Result<Frames> encode_status(const StreamMessage& message, const StatusReport& status) {
  for (double ms :
       {status.arrangement_ms, status.field_ms, status.smoothing_ms, status.mesh_ms,
        status.total_ms, status.update_ms.value_or(0.0), status.latency_ms.value_or(0.0)})
    if (!std::isfinite(ms) || ms < 0.0)
      return Status::error("cannot encode status: a stage time is negative or not finite");
  if (status.state == ScanState::kError && status.message.empty())
    return Status::error("cannot encode status: state error needs a message saying what failed");
  if (status.finished && status.state == ScanState::kScanning)
    return Status::error("cannot encode status: a finished scan is idle or error, not scanning");
  if (status.frame_rate_hz &&
      !(std::isfinite(*status.frame_rate_hz) && *status.frame_rate_hz >= 0.0))
    return Status::error("cannot encode status: frame_rate_hz is negative or not finite");
  ordered_json header;
  header["v"] = kMeshStreamVersion;
  header["seq"] = message.seq;
  header["scan"] = message.scan;
  header["frames_received"] = status.frames_received;
  header["frames_dropped"] = status.frames_dropped;
  header["slices"] = status.slices;
  header["arrangement_ms"] = status.arrangement_ms;
  header["field_ms"] = status.field_ms;
  header["smoothing_ms"] = status.smoothing_ms;
  header["mesh_ms"] = status.mesh_ms;
  header["total_ms"] = status.total_ms;
  if (status.update_ms) header["update_ms"] = *status.update_ms;
  if (status.latency_ms) header["latency_ms"] = *status.latency_ms;
  header["state"] = std::string(to_string(status.state));
  if (!status.message.empty()) header["message"] = status.message;
  // Both optional, so that the headers of older publishers still read (mesh-stream.md).
  if (status.frame_rate_hz) header["frame_rate_hz"] = *status.frame_rate_hz;
  if (status.finished) header["finished"] = true;
  return Frames{std::string(kStatusTopic), header.dump()};
}

Frames encode_end(const StreamMessage& message) {
  ordered_json header;
  header["v"] = kMeshStreamVersion;
  header["seq"] = message.seq;
  header["scan"] = message.scan;
  return Frames{std::string(kEndTopic), header.dump()};
}

// ---------------------------------------------------------------------------------------------
// Decoding: every problem is thrown as InputError inside, returned as a Status outside.

[[noreturn]] void invalid(std::string what) { throw InputError("", std::move(what)); }

// Printable form of received text for messages: at most 40 characters, control bytes escaped.
std::string printable(std::string_view text) {
  std::string out = "\"";
  for (std::size_t k = 0; k < text.size() && k < 40; ++k) {
    const auto c = static_cast<unsigned char>(text[k]);
    if (c >= 0x20 && c < 0x7f && c != '"' && c != '\\') {
      out += static_cast<char>(c);
    } else {
      static const char* kHex = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0xf];
    }
  }
  if (text.size() > 40) out += "...";
  return out + "\"";
}

std::string short_dump(const json& j) {
  std::string text = j.dump(-1, ' ', false, json::error_handler_t::replace);
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return text;
}

const json& required(const json& header, const char* key) {
  const auto it = header.find(key);
  if (it == header.end()) invalid(std::string("\"") + key + "\" is missing from the header");
  return *it;
}

constexpr std::uint64_t kMaxSeq = (std::uint64_t{1} << 53) - 1;

std::uint64_t read_count(const json& header, const char* key) {
  const json& j = required(header, key);
  if (!j.is_number_unsigned())
    invalid(std::string("\"") + key + "\" must be an integer >= 0, got " + short_dump(j));
  return j.get<std::uint64_t>();
}

double read_finite(const json& header, const char* key) {
  const json& j = required(header, key);
  if (!j.is_number() || !std::isfinite(j.get<double>()))
    invalid(std::string("\"") + key + "\" must be a finite number, got " + short_dump(j));
  return j.get<double>();
}

std::string read_string(const json& header, const char* key) {
  const json& j = required(header, key);
  if (!j.is_string())
    invalid(std::string("\"") + key + "\" must be a string, got " + short_dump(j));
  return j.get<std::string>();
}

void check_version(const json& header, bool optional) {
  const auto it = header.find("v");
  if (it == header.end()) {
    if (optional) return;
    invalid("\"v\" is missing from the header; version 1 headers carry \"v\": 1");
  }
  if (!it->is_number_integer() || it->get<long long>() != kMeshStreamVersion)
    invalid("unknown format version \"v\": " + short_dump(*it) +
            "; this receiver reads v 1, a newer publisher needs a newer receiver");
}

Vec3 read_vec3(const json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3) invalid(where + " must be [x, y, z], got " + short_dump(j));
  Vec3 v;
  for (int k = 0; k < 3; ++k) {
    if (!j[k].is_number() || !std::isfinite(j[k].get<double>()))
      invalid(where + " must hold 3 finite numbers, got " + short_dump(j));
    v[k] = j[k].get<double>();
  }
  return v;
}

void check_frame_count(const Frames& frames, std::size_t wanted, const std::string& what) {
  if (frames.size() != wanted)
    invalid("the message has " + std::to_string(frames.size()) + " frames, " + what + " has " +
            std::to_string(wanted));
}

// Label of a canonical "mesh.<id>" topic (id >= 1, decimal, no sign or leading zero), else 0.
int mesh_topic_label(std::string_view topic) {
  if (topic.substr(0, kMeshTopicPrefix.size()) != kMeshTopicPrefix) return 0;
  const std::string_view digits = topic.substr(kMeshTopicPrefix.size());
  if (digits.empty() || digits.front() == '0') return 0;
  int label = 0;
  const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), label);
  if (ec != std::errc() || end != digits.data() + digits.size() || label < 1) return 0;
  return label;
}

// Each frame of a mesh message holds exactly what its counts need.
void check_mesh_frame_sizes(const Frames& frames, std::uint64_t vertex_count,
                            std::uint64_t triangle_count, bool normals) {
  auto check_size = [&](std::size_t frame, std::uint64_t count, std::size_t bytes_each,
                        const char* count_key, const char* what) {
    const std::size_t size = frames[frame].size();
    if (size % bytes_each != 0 || size / bytes_each != count)
      invalid("frame " + std::to_string(frame) + " holds " + std::to_string(size) + " bytes but " +
              count_key + " " + std::to_string(count) + " needs " +
              (count <= std::numeric_limits<std::uint64_t>::max() / bytes_each
                   ? std::to_string(count * bytes_each)
                   : std::string("more")) +
              " (" + what + ")");
  };
  check_size(2, vertex_count, kVertexBytes, "vertex_count", "3 float32 per vertex");
  check_size(3, triangle_count, kTriangleBytes, "triangle_count", "3 uint32 per triangle");
  if (normals) check_size(4, vertex_count, kVertexBytes, "vertex_count", "3 float32 per normal");
}

// The vertices, triangles and normals of a mesh message whose frame sizes were checked: finite
// coordinates, vertex indices in range.
void read_mesh_arrays(const Frames& frames, std::uint64_t vertex_count,
                      std::uint64_t triangle_count, bool normals, MeshUpdate& update) {
  update.mesh.vertices = f32_to_vec3s(frames[2]);
  for (std::size_t k = 0; k < update.mesh.vertices.size(); ++k)
    if (!update.mesh.vertices[k].allFinite())
      invalid("vertex " + std::to_string(k) + " is NaN or infinite");
  update.mesh.triangles.resize(triangle_count);
  const char* p = frames[3].data();
  for (std::size_t t = 0; t < update.mesh.triangles.size(); ++t)
    for (std::uint32_t& index : update.mesh.triangles[t]) {
      index = get_u32(p);
      p += 4;
      if (index >= vertex_count)
        invalid("triangle " + std::to_string(t) + " uses vertex index " + std::to_string(index) +
                ", out of range for vertex_count " + std::to_string(vertex_count));
    }
  if (normals) {
    update.normals = f32_to_vec3s(frames[4]);
    for (std::size_t k = 0; k < update.normals->size(); ++k)
      if (!(*update.normals)[k].allFinite())
        invalid("normal " + std::to_string(k) + " is NaN or infinite");
  }
}

// The header's "bounds": null exactly for an empty mesh, else a box holding every vertex (to a
// relative tolerance).
std::optional<Box3> read_mesh_bounds(const json& header, const TriangleMesh& mesh) {
  const json& bounds = required(header, "bounds");
  if (bounds.is_null()) {
    if (!mesh.vertices.empty()) invalid("\"bounds\" is null but the mesh has vertices");
    return std::nullopt;
  }
  if (mesh.vertices.empty())
    invalid("\"bounds\" is " + short_dump(bounds) +
            " but the mesh is empty; an empty mesh has \"bounds\": null");
  if (!bounds.is_object() || !bounds.contains("min") || !bounds.contains("max"))
    invalid("\"bounds\" must be {\"min\": [x, y, z], \"max\": [x, y, z]}, got " +
            short_dump(bounds));
  Box3 box{read_vec3(bounds["min"], "\"bounds\" min"), read_vec3(bounds["max"], "\"bounds\" max")};
  if ((box.min.array() > box.max.array()).any())
    invalid("\"bounds\" min is above max on some axis");
  const double tol =
      kBoundsRelTol * std::max({1.0, box.min.cwiseAbs().maxCoeff(), box.max.cwiseAbs().maxCoeff()});
  const Box3 loose = box.padded(tol);
  for (std::size_t k = 0; k < mesh.vertices.size(); ++k)
    if (!loose.contains(mesh.vertices[k]))
      invalid("vertex " + std::to_string(k) + " lies outside \"bounds\"");
  return box;
}

MeshUpdate decode_mesh(const Frames& frames, const json& header, int topic_label) {
  MeshUpdate update;
  const json& label = required(header, "label");
  if (!label.is_number_integer() || label.get<long long>() != topic_label)
    invalid("\"label\" is " + short_dump(label) + " but the topic names label " +
            std::to_string(topic_label));
  update.label = topic_label;
  update.name = read_string(header, "name");
  update.units = read_string(header, "units");
  update.frame = read_string(header, "frame");
  update.timestamp_s = read_finite(header, "timestamp_s");
  update.slices = read_count(header, "slices");
  const std::uint64_t vertex_count = read_count(header, "vertex_count");
  const std::uint64_t triangle_count = read_count(header, "triangle_count");
  bool normals = false;
  if (const auto it = header.find("normals"); it != header.end()) {
    if (!it->is_boolean()) invalid("\"normals\" must be true or false, got " + short_dump(*it));
    normals = it->get<bool>();
  }
  check_frame_count(
      frames, normals ? 5 : 4,
      normals ? "a mesh message with \"normals\": true" : "a mesh message without normals");
  check_mesh_frame_sizes(frames, vertex_count, triangle_count, normals);
  read_mesh_arrays(frames, vertex_count, triangle_count, normals, update);
  if (const std::optional<Box3> bounds = read_mesh_bounds(header, update.mesh))
    update.bounds = *bounds;
  return update;
}

PlaneFrame read_plane(const json& header) {
  const json& plane = required(header, "plane");
  if (!plane.is_object())
    invalid("\"plane\" must be {\"origin\": [x, y, z], \"u\": [..], \"v\": [..]}, got " +
            short_dump(plane));
  PlaneFrame out;
  out.origin_mm = read_vec3(required(plane, "origin"), "\"plane\" origin");
  out.u = read_vec3(required(plane, "u"), "\"plane\" u");
  out.v = read_vec3(required(plane, "v"), "\"plane\" v");
  return out;
}

// The slice object of slices.md inside a slice header: the plane's origin, u and v at the top
// level again, and every key that is not the message's own.
std::string slice_object_of(const json& header) {
  const json& plane = required(header, "plane");
  if (!plane.is_object())
    invalid("\"plane\" must be {\"origin\": [x, y, z], \"u\": [..], \"v\": [..]}, got " +
            short_dump(plane));
  json object = json::object();
  for (const char* key : {"origin", "u", "v"}) {
    if (!plane.contains(key)) invalid(std::string("\"plane\" ") + key + " is missing");
    object[key] = plane[key];
  }
  for (const auto& [key, value] : header.items())
    if (key != "v" && key != "seq" && key != "scan" && key != "index" && key != "plane" &&
        key != "origin" && key != "u")
      object[key] = value;
  return object.dump();
}

FrameImage decode_frame(const Frames& frames, const json& header) {
  check_frame_count(frames, 3, "a frame message");
  FrameImage frame;
  const json& index = required(header, "index");
  if (!index.is_number_integer() || index.get<long long>() < 0)
    invalid("\"index\" must be an integer >= 0, got " + short_dump(index));
  frame.index = index.get<std::int64_t>();
  frame.timestamp_s = read_finite(header, "timestamp_s");
  if (const std::string format = read_string(header, "format"); format != "gray8")
    invalid("unknown \"format\" " + printable(format) + " (gray8)");
  const std::uint64_t width = read_count(header, "width");
  const std::uint64_t height = read_count(header, "height");
  const auto side = static_cast<std::uint64_t>(kMaxFrameImageSide);
  if (width < 1 || height < 1 || width > side || height > side)
    invalid("a picture of " + std::to_string(width) + " x " + std::to_string(height) +
            " px; width and height are 1 to " + std::to_string(side));
  if (frames[2].size() != width * height)
    invalid("frame 2 holds " + std::to_string(frames[2].size()) + " bytes but width * height is " +
            std::to_string(width * height) + " (one byte per pixel)");
  frame.plane = read_plane(header);
  if (!orthonormal(frame.plane)) invalid("\"plane\" u and v must be unit and orthogonal");
  const json& size = required(header, "size_mm");
  if (!size.is_array() || size.size() != 2 || !size[0].is_number() || !size[1].is_number() ||
      !(size[0].get<double>() > 0.0) || !(size[1].get<double>() > 0.0) ||
      !std::isfinite(size[0].get<double>()) || !std::isfinite(size[1].get<double>()))
    invalid("\"size_mm\" must be [width, height] in mm, both > 0, got " + short_dump(size));
  frame.size_mm = Vec2(size[0].get<double>(), size[1].get<double>());
  frame.image.width = static_cast<int>(width);
  frame.image.height = static_cast<int>(height);
  frame.image.pixels.assign(frames[2].begin(), frames[2].end());
  return frame;
}

StatusReport decode_status(const json& header) {
  StatusReport status;
  status.frames_received = read_count(header, "frames_received");
  status.frames_dropped = read_count(header, "frames_dropped");
  status.slices = read_count(header, "slices");
  const std::pair<const char*, double*> times[] = {{"arrangement_ms", &status.arrangement_ms},
                                                   {"field_ms", &status.field_ms},
                                                   {"smoothing_ms", &status.smoothing_ms},
                                                   {"mesh_ms", &status.mesh_ms},
                                                   {"total_ms", &status.total_ms}};
  for (const auto& [key, value] : times) {
    *value = read_finite(header, key);
    if (*value < 0.0) invalid(std::string("\"") + key + "\" is negative");
  }
  for (auto [key, value] :
       {std::pair{"update_ms", &status.update_ms}, std::pair{"latency_ms", &status.latency_ms}})
    if (header.contains(key)) {
      *value = read_finite(header, key);
      if (**value < 0.0) invalid(std::string("\"") + key + "\" is negative");
    }
  const std::string state = read_string(header, "state");
  if (state == "scanning")
    status.state = ScanState::kScanning;
  else if (state == "idle")
    status.state = ScanState::kIdle;
  else if (state == "error")
    status.state = ScanState::kError;
  else
    invalid("unknown \"state\" " + printable(state) + " (scanning, idle or error)");
  if (header.contains("message")) status.message = read_string(header, "message");
  if (status.state == ScanState::kError && status.message.empty())
    invalid("state \"error\" without a \"message\" saying what failed");
  if (header.contains("frame_rate_hz")) {
    status.frame_rate_hz = read_finite(header, "frame_rate_hz");
    if (*status.frame_rate_hz < 0.0) invalid("\"frame_rate_hz\" is negative");
  }
  if (header.contains("finished")) {
    if (!header["finished"].is_boolean()) invalid("\"finished\" is not true or false");
    status.finished = header["finished"].get<bool>();
    if (status.finished && status.state == ScanState::kScanning)
      invalid("\"finished\" with state \"scanning\" (a finished scan is idle or error)");
  }
  return status;
}

}  // namespace

std::string StreamMessage::topic() const {
  struct {
    std::string operator()(const MeshUpdate& m) const {
      return std::string(kMeshTopicPrefix) + std::to_string(m.label);
    }
    std::string operator()(const SliceUpdate&) const { return std::string(kSliceTopic); }
    std::string operator()(const StatusReport&) const { return std::string(kStatusTopic); }
    std::string operator()(const FrameImage&) const { return std::string(kFrameTopic); }
    std::string operator()(const SnapshotEnd&) const { return std::string(kEndTopic); }
  } visitor;
  return std::visit(visitor, body);
}

Result<Frames> encode_message(const StreamMessage& message) {
  const bool is_end = std::holds_alternative<SnapshotEnd>(message.body);
  if (message.scan.empty()) return Status::error("cannot encode a message without a scan uuid");
  if (message.seq == 0 && !is_end)
    return Status::error("cannot encode " + message.topic() + " with seq 0: seq starts at 1");
  if (const auto* mesh = std::get_if<MeshUpdate>(&message.body)) return encode_mesh(message, *mesh);
  if (const auto* slice = std::get_if<SliceUpdate>(&message.body))
    return encode_slice(message, *slice);
  if (const auto* status = std::get_if<StatusReport>(&message.body))
    return encode_status(message, *status);
  if (const auto* frame = std::get_if<FrameImage>(&message.body))
    return encode_frame(message, *frame);
  return encode_end(message);
}

Result<StreamMessage> decode_message(const Frames& frames) {
  if (frames.empty()) return Status::error("empty message (no frames)");
  const std::string& topic = frames.front();
  const int label = mesh_topic_label(topic);
  const bool is_end = topic == kEndTopic;
  if (label == 0 && topic != kSliceTopic && topic != kStatusTopic && topic != kFrameTopic &&
      !is_end)
    return Status::error("unknown topic " + printable(topic) +
                         " (expected mesh.<label id>, slice, status, frame or end)");
  std::string where = topic;  // grows to "topic seq N" once the seq is known
  StreamMessage message;
  try {
    if (frames.size() < 2) invalid("no header (frame 1)");
    json header;
    try {
      header = json::parse(frames[1]);
    } catch (const json::exception&) {
      invalid("the header (frame 1) is not valid JSON: " + printable(frames[1]));
    }
    if (!header.is_object()) invalid("the header (frame 1) is not a JSON object");
    check_version(header, /*optional=*/is_end);
    message.seq = read_count(header, "seq");
    where += " seq " + std::to_string(message.seq);
    if (message.seq == 0 && !is_end) invalid("seq 0: seq starts at 1");
    // A seq counts messages from 1: it never nears 2^53, the largest integer the page's
    // JavaScript keeps exactly. A larger one is a lie that would make a late joiner drop every
    // live message as covered by the snapshot.
    if (message.seq > kMaxSeq)
      invalid("seq " + std::to_string(message.seq) + " is above 2^53 - 1 = " +
              std::to_string(kMaxSeq) + "; seq counts the scan's messages from 1");
    if (!is_end || header.contains("scan")) {
      message.scan = read_string(header, "scan");
      if (message.scan.empty()) invalid("\"scan\" is empty; it names the scan by its uuid");
    }

    if (label != 0) {
      message.body = decode_mesh(frames, header, label);
    } else if (topic == kSliceTopic) {
      check_frame_count(frames, 2, "a slice message");
      SliceUpdate update;
      update.index = read_count(header, "index");
      Result<LabeledSlice> slice = parse_slice_json(slice_object_of(header), where);
      if (!slice) return slice.status();  // already prefixed with `where`
      update.slice = std::move(*slice);
      message.body = std::move(update);
    } else if (topic == kFrameTopic) {
      message.body = decode_frame(frames, header);
    } else if (topic == kStatusTopic) {
      check_frame_count(frames, 2, "a status message");
      message.body = decode_status(header);
    } else {
      check_frame_count(frames, 2, "an end message");
      message.body = SnapshotEnd{};
    }
  } catch (const InputError& problem) {
    return Status::error(problem.message_in(where));
  } catch (const json::exception& e) {
    return Status::error(where + ": malformed header (" + std::string(e.what()) + ")");
  }
  return message;
}

}  // namespace sonoshape::publish
