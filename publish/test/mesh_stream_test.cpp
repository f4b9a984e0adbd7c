// Mesh-stream messages: encode/decode round trips and every rejection of the validating decoder.
#include "sonoshape/publish/mesh_stream.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>

#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::publish::mesh_stream_test {
namespace {

using nlohmann::json;
using sonoshape::testing::contains;

const char* kScan = "0f8fad5b-d9cb-469f-a165-70867728950e";

// A tetrahedron with float-exact coordinates, outward triangles.
TriangleMesh tetrahedron(double offset = 0.0) {
  TriangleMesh mesh;
  mesh.vertices = {Vec3(offset, 0, 0), Vec3(offset + 1, 0, 0), Vec3(offset, 1, 0),
                   Vec3(offset, 0, 1.5)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

StreamMessage mesh_message(std::uint64_t seq = 7, int label = 2) {
  MeshUpdate update;
  update.label = label;
  update.name = "kidney";
  update.timestamp_s = 12.5;
  update.slices = 17;
  update.mesh = tetrahedron(-2.0);
  return StreamMessage{seq, kScan, update};
}

LabeledSlice sample_slice() {
  LabeledSlice slice;
  slice.origin_mm = Vec3(1.5, -2, 12.25);
  slice.u = Vec3(0, 1, 0);
  slice.v = Vec3(0, 0, 1);
  slice.timestamp_s = 0.033;
  slice.fov = Ring2{Vec2(-40, 0), Vec2(40, 0), Vec2(40, 60), Vec2(-40, 60)};
  Region organ;
  organ.label = 1;
  organ.outer = {Vec2(-10, 5), Vec2(12, 5), Vec2(12, 30), Vec2(-10, 30)};
  organ.holes = {{Vec2(0, 10), Vec2(4, 10), Vec2(4, 14), Vec2(0, 14)}};
  Region shadow;
  shadow.label = kUnknownLabel;
  shadow.outer = {Vec2(20, 40), Vec2(30, 40), Vec2(25, 50)};
  slice.regions = {organ, shadow};
  return slice;
}

StatusReport sample_status() {
  StatusReport status;
  status.frames_received = 120;
  status.frames_dropped = 3;
  status.slices = 40;
  status.arrangement_ms = 1.25;
  status.field_ms = 20.5;
  status.smoothing_ms = 3.0;
  status.mesh_ms = 4.75;
  status.total_ms = 29.5;
  status.update_ms = 31.0;
  status.latency_ms = 142.5;
  return status;
}

Frames encoded(const StreamMessage& message) {
  Result<Frames> frames = encode_message(message);
  EXPECT_TRUE(frames.is_ok()) << frames.message();
  return frames ? *frames : Frames{};
}

// The frames with the header changed by `edit`.
template <typename Edit>
Frames with_header(Frames frames, Edit edit) {
  json header = json::parse(frames[1]);
  edit(header);
  frames[1] = header.dump();
  return frames;
}

// Decoding must fail with a message that holds every part of `expected`.
void expect_rejected(const Frames& frames, std::initializer_list<std::string> expected) {
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_FALSE(decoded.is_ok()) << "accepted a malformed message";
  for (const std::string& part : expected)
    EXPECT_TRUE(contains(decoded.message(), part)) << decoded.message() << "\nlacks: " << part;
}

void put_float(std::string& bytes, std::size_t index, float value) {
  std::memcpy(bytes.data() + 4 * index, &value, 4);  // tests run on little-endian hosts
}

void put_u32(std::string& bytes, std::size_t index, std::uint32_t value) {
  std::memcpy(bytes.data() + 4 * index, &value, 4);
}

TEST(MeshStreamRoundTrip, MeshKeepsEveryField) {
  const StreamMessage original = mesh_message();
  const Frames frames = encoded(original);
  ASSERT_EQ(frames.size(), 4u);
  EXPECT_EQ(frames[0], "mesh.2");
  EXPECT_EQ(frames[2].size(), 4u * 12);
  EXPECT_EQ(frames[3].size(), 4u * 12);
  const json header = json::parse(frames[1]);
  for (const char* key : {"v", "seq", "scan", "label", "name", "units", "frame", "timestamp_s",
                          "slices", "vertex_count", "triangle_count", "bounds"})
    EXPECT_TRUE(header.contains(key)) << key;
  EXPECT_EQ(header["v"], 1);
  EXPECT_EQ(header["units"], "mm");
  EXPECT_EQ(header["frame"], "reference");
  EXPECT_FALSE(header.contains("normals"));

  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_EQ(decoded->seq, 7u);
  EXPECT_EQ(decoded->scan, kScan);
  EXPECT_EQ(decoded->topic(), "mesh.2");
  const auto& update = std::get<MeshUpdate>(decoded->body);
  const auto& sent = std::get<MeshUpdate>(original.body);
  EXPECT_EQ(update.label, 2);
  EXPECT_EQ(update.name, "kidney");
  EXPECT_EQ(update.units, "mm");
  EXPECT_EQ(update.frame, "reference");
  EXPECT_EQ(update.timestamp_s, 12.5);
  EXPECT_EQ(update.slices, 17u);
  EXPECT_EQ(update.mesh.vertices, sent.mesh.vertices);
  EXPECT_EQ(update.mesh.triangles, sent.mesh.triangles);
  EXPECT_FALSE(update.normals.has_value());
  ASSERT_TRUE(update.bounds.has_value());
  EXPECT_EQ(update.bounds->min, Vec3(-2, 0, 0));
  EXPECT_EQ(update.bounds->max, Vec3(-1, 1, 1.5));
}

TEST(MeshStreamRoundTrip, MeshWithNormals) {
  StreamMessage message = mesh_message();
  auto& update = std::get<MeshUpdate>(message.body);
  update.normals = std::vector<Vec3>(4, Vec3(0, 0, 1));
  const Frames frames = encoded(message);
  ASSERT_EQ(frames.size(), 5u);
  EXPECT_EQ(json::parse(frames[1])["normals"], true);
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_EQ(std::get<MeshUpdate>(decoded->body).normals, update.normals);
}

TEST(MeshStreamRoundTrip, VanishedMaterialIsAnEmptyMesh) {
  StreamMessage message = mesh_message();
  std::get<MeshUpdate>(message.body).mesh = TriangleMesh{};
  const Frames frames = encoded(message);
  EXPECT_TRUE(frames[2].empty());
  EXPECT_TRUE(frames[3].empty());
  EXPECT_TRUE(json::parse(frames[1])["bounds"].is_null());
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  const auto& update = std::get<MeshUpdate>(decoded->body);
  EXPECT_TRUE(update.mesh.vertices.empty());
  EXPECT_FALSE(update.bounds.has_value());
}

TEST(MeshStreamRoundTrip, SliceCarriesTheVersionAndItsPlaneUnderPlane) {
  const LabeledSlice slice = sample_slice();
  const Frames frames = encoded(StreamMessage{9, kScan, SliceUpdate{4, slice}});
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0], "slice");
  EXPECT_EQ(frames[1].find('\n'), std::string::npos);
  const json header = json::parse(frames[1]);
  EXPECT_EQ(header["v"], 1);  // the version, as in every header
  EXPECT_EQ(header["seq"], 9);
  EXPECT_EQ(header["index"], 4);
  EXPECT_EQ(header["plane"]["origin"], json::array({1.5, -2, 12.25}));
  EXPECT_EQ(header["plane"]["u"], json::array({0, 1, 0}));
  EXPECT_EQ(header["plane"]["v"], json::array({0, 0, 1}));
  EXPECT_FALSE(header.contains("origin"));
  EXPECT_FALSE(header.contains("u"));
  EXPECT_EQ(header["regions"][1]["label"], "unknown");
  EXPECT_EQ(header["fov"].size(), 4u);

  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_EQ(decoded->seq, 9u);
  EXPECT_EQ(decoded->scan, kScan);
  const auto& update = std::get<SliceUpdate>(decoded->body);
  EXPECT_EQ(update.index, 4u);
  EXPECT_EQ(update.slice.origin_mm, slice.origin_mm);
  EXPECT_EQ(update.slice.u, slice.u);
  EXPECT_EQ(update.slice.v, slice.v);
  EXPECT_EQ(update.slice.timestamp_s, slice.timestamp_s);
  EXPECT_EQ(update.slice.fov, slice.fov);
  ASSERT_EQ(update.slice.regions.size(), 2u);
  EXPECT_EQ(update.slice.regions[0].outer, slice.regions[0].outer);
  EXPECT_EQ(update.slice.regions[0].holes, slice.regions[0].holes);
  EXPECT_EQ(update.slice.regions[1].label, kUnknownLabel);
}

TEST(MeshStreamRoundTrip, SliceDirectionsAreExactAfterTheRoundTrip) {
  // Directions that are not round in binary: the header's numbers must read back bit for bit.
  LabeledSlice slice = sample_slice();
  slice.u = Vec3(std::cos(0.3), std::sin(0.3), 0.0);
  slice.v = Vec3(-std::sin(0.3) * std::cos(1.1), std::cos(0.3) * std::cos(1.1), std::sin(1.1));
  slice.origin_mm = Vec3(0.1, 1.0 / 3.0, -7.0 / 9.0);
  Result<StreamMessage> decoded =
      decode_message(encoded(StreamMessage{2, kScan, SliceUpdate{0, slice}}));
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  const auto& got = std::get<SliceUpdate>(decoded->body).slice;
  EXPECT_EQ(got.u, slice.u);
  EXPECT_EQ(got.v, slice.v);
  EXPECT_EQ(got.origin_mm, slice.origin_mm);
}

FrameImage sample_frame() {
  FrameImage frame;
  frame.index = 31;
  frame.timestamp_s = 1.25;
  frame.image = GreyImage(3, 2);
  frame.image.pixels = {0, 50, 100, 150, 200, 255};
  frame.plane.origin_mm = Vec3(-20, 0, 5);
  frame.plane.u = Vec3(1, 0, 0);
  frame.plane.v = Vec3(0, 0, -1);
  frame.size_mm = Vec2(40, 30);
  return frame;
}

TEST(MeshStreamRoundTrip, FrameIsAGreyPictureOnItsPlane) {
  const Frames frames = encoded(StreamMessage{12, kScan, sample_frame()});
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[0], "frame");
  const json header = json::parse(frames[1]);
  EXPECT_EQ(header["v"], 1);
  EXPECT_EQ(header["format"], "gray8");
  EXPECT_EQ(header["width"], 3);
  EXPECT_EQ(header["height"], 2);
  EXPECT_EQ(header["plane"]["v"], json::array({0, 0, -1}));
  EXPECT_EQ(header["size_mm"], json::array({40, 30}));
  EXPECT_EQ(frames[2], std::string("\x00\x32\x64\x96\xc8\xff", 6));
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_EQ(decoded->seq, 12u);
  const auto& got = std::get<FrameImage>(decoded->body);
  EXPECT_EQ(got.index, 31);
  EXPECT_EQ(got.timestamp_s, 1.25);
  EXPECT_EQ(got.image, sample_frame().image);
  EXPECT_EQ(got.plane.origin_mm, Vec3(-20, 0, 5));
  EXPECT_EQ(got.plane.v, Vec3(0, 0, -1));
  EXPECT_EQ(got.size_mm, Vec2(40, 30));
}

TEST(MeshStreamEncode, RefusesFramesThatAreNotPreviews) {
  FrameImage empty = sample_frame();
  empty.image = GreyImage();
  EXPECT_TRUE(contains(encode_message(StreamMessage{1, kScan, empty}).message(), "0 x 0 px"));
  FrameImage huge = sample_frame();
  huge.image = GreyImage(kMaxFrameImageSide + 1, 1);
  EXPECT_TRUE(contains(encode_message(StreamMessage{1, kScan, huge}).message(), "downsample"));
  FrameImage skew = sample_frame();
  skew.plane.v = Vec3(1, 0, 1).normalized();
  EXPECT_TRUE(contains(encode_message(StreamMessage{1, kScan, skew}).message(), "orthogonal"));
  FrameImage flat = sample_frame();
  flat.size_mm.y() = 0.0;
  EXPECT_TRUE(contains(encode_message(StreamMessage{1, kScan, flat}).message(), "positive"));
}

TEST(MeshStreamDecode, RejectsBadFrames) {
  const Frames good = encoded(StreamMessage{12, kScan, sample_frame()});
  Frames short_pixels = good;
  short_pixels[2].pop_back();
  expect_rejected(short_pixels, {"frame seq 12", "frame 2 holds 5 bytes but width * height is 6"});
  expect_rejected(with_header(good, [](json& h) { h["format"] = "rgb8"; }),
                  {"unknown \"format\" \"rgb8\""});
  expect_rejected(with_header(good, [](json& h) { h["width"] = 0; }), {"width and height"});
  expect_rejected(with_header(good,
                              [](json& h) {
                                h["plane"]["u"] = {0, 0, 2};
                              }),
                  {"unit and orthogonal"});
  expect_rejected(with_header(good, [](json& h) { h["size_mm"] = {40, -1}; }), {"\"size_mm\""});
  for (const char* key : {"index", "timestamp_s", "format", "width", "height", "plane", "size_mm"})
    expect_rejected(with_header(good, [&](json& h) { h.erase(key); }),
                    {"frame", std::string("\"") + key + "\" is missing"});
  Frames no_pixels = good;
  no_pixels.pop_back();
  expect_rejected(no_pixels, {"2 frames", "a frame message has 3"});
}

TEST(MeshStreamRoundTrip, StatusKeepsEveryField) {
  StatusReport status = sample_status();
  status.state = ScanState::kError;
  status.message = "tracker lost";
  const Frames frames = encoded(StreamMessage{3, kScan, status});
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0], "status");
  EXPECT_EQ(json::parse(frames[1])["state"], "error");
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  const auto& got = std::get<StatusReport>(decoded->body);
  EXPECT_EQ(got.frames_received, 120u);
  EXPECT_EQ(got.frames_dropped, 3u);
  EXPECT_EQ(got.slices, 40u);
  EXPECT_EQ(got.arrangement_ms, 1.25);
  EXPECT_EQ(got.field_ms, 20.5);
  EXPECT_EQ(got.smoothing_ms, 3.0);
  EXPECT_EQ(got.mesh_ms, 4.75);
  EXPECT_EQ(got.total_ms, 29.5);
  EXPECT_EQ(got.update_ms, 31.0);
  EXPECT_EQ(got.latency_ms, 142.5);
  EXPECT_EQ(got.state, ScanState::kError);
  EXPECT_EQ(got.message, "tracker lost");
  for (ScanState state : {ScanState::kScanning, ScanState::kIdle}) {
    status.state = state;
    status.message.clear();
    Result<StreamMessage> again = decode_message(encoded(StreamMessage{4, kScan, status}));
    ASSERT_TRUE(again.is_ok()) << again.message();
    EXPECT_EQ(std::get<StatusReport>(again->body).state, state);
  }
}

// Issue 40, "a finished scan reads as finished": the scan's last status says so, with its final
// counts, and how many frames a second the scan publishes (0: a view says why it shows none).
// Both fields are optional: an older publisher's status reads as before.
TEST(MeshStreamRoundTrip, TheLastStatusSaysTheScanFinishedAndTheFrameRate) {
  StatusReport status = sample_status();
  const Frames plain = encoded(StreamMessage{3, kScan, status});
  EXPECT_FALSE(json::parse(plain[1]).contains("finished"));
  EXPECT_FALSE(json::parse(plain[1]).contains("frame_rate_hz"));
  Result<StreamMessage> older = decode_message(plain);
  ASSERT_TRUE(older.is_ok()) << older.message();
  EXPECT_FALSE(std::get<StatusReport>(older->body).finished);
  EXPECT_FALSE(std::get<StatusReport>(older->body).frame_rate_hz.has_value());

  status.state = ScanState::kIdle;
  status.message = "scan finished (source ended)";
  status.finished = true;
  status.frame_rate_hz = 0.0;
  const Frames last = encoded(StreamMessage{9, kScan, status});
  EXPECT_EQ(json::parse(last[1])["finished"], true);
  EXPECT_EQ(json::parse(last[1])["frame_rate_hz"], 0.0);
  Result<StreamMessage> decoded = decode_message(last);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  const auto& got = std::get<StatusReport>(decoded->body);
  EXPECT_TRUE(got.finished);
  EXPECT_EQ(got.frame_rate_hz, 0.0);
  EXPECT_EQ(got.slices, 40u);
  EXPECT_EQ(got.frames_received, 120u);

  expect_rejected(with_header(last, [](json& h) { h["state"] = "scanning"; }),
                  {"\"finished\" with state \"scanning\""});
  expect_rejected(with_header(last, [](json& h) { h["finished"] = 1; }),
                  {"\"finished\" is not true or false"});
  expect_rejected(with_header(last, [](json& h) { h["frame_rate_hz"] = -5.0; }),
                  {"\"frame_rate_hz\" is negative"});
  status.state = ScanState::kScanning;
  EXPECT_FALSE(encode_message(StreamMessage{10, kScan, status}).is_ok());
}

TEST(MeshStreamRoundTrip, StatusBeforeTheFirstUpdateHasNoLatency) {
  StatusReport status = sample_status();
  status.update_ms.reset();
  status.latency_ms.reset();
  const Frames frames = encoded(StreamMessage{3, kScan, status});
  EXPECT_FALSE(json::parse(frames[1]).contains("latency_ms"));
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_FALSE(std::get<StatusReport>(decoded->body).latency_ms.has_value());
  EXPECT_FALSE(std::get<StatusReport>(decoded->body).update_ms.has_value());
  expect_rejected(with_header(frames, [](json& h) { h["latency_ms"] = -2.0; }),
                  {"\"latency_ms\" is negative"});
}

TEST(MeshStreamRoundTrip, EndCarriesTheSeq) {
  const Frames frames = encoded(StreamMessage{0, kScan, SnapshotEnd{}});
  EXPECT_EQ(frames[0], "end");
  Result<StreamMessage> decoded = decode_message(frames);
  ASSERT_TRUE(decoded.is_ok()) << decoded.message();
  EXPECT_EQ(decoded->seq, 0u);
  EXPECT_TRUE(std::holds_alternative<SnapshotEnd>(decoded->body));
  // The format's minimal form, {"seq": N}, is accepted too.
  Result<StreamMessage> minimal = decode_message(Frames{"end", R"({"seq": 41})"});
  ASSERT_TRUE(minimal.is_ok()) << minimal.message();
  EXPECT_EQ(minimal->seq, 41u);
}

TEST(MeshStreamEncode, RefusesWhatTheFormatCannotCarry) {
  StreamMessage nan_vertex = mesh_message();
  std::get<MeshUpdate>(nan_vertex.body).mesh.vertices[1].y() = std::nan("");
  EXPECT_TRUE(contains(encode_message(nan_vertex).message(), "NaN"));

  StreamMessage bad_index = mesh_message();
  std::get<MeshUpdate>(bad_index.body).mesh.triangles[2][1] = 4;
  EXPECT_TRUE(contains(encode_message(bad_index).message(), "triangle 2 uses vertex 4 of 4"));

  EXPECT_TRUE(contains(encode_message(mesh_message(7, 0)).message(), "label 0"));
  EXPECT_TRUE(contains(encode_message(mesh_message(0)).message(), "seq 0"));

  StreamMessage no_scan = mesh_message();
  no_scan.scan.clear();
  EXPECT_FALSE(encode_message(no_scan).is_ok());

  StatusReport error = sample_status();
  error.state = ScanState::kError;
  EXPECT_TRUE(contains(encode_message(StreamMessage{1, kScan, error}).message(), "message"));

  LabeledSlice infinite = sample_slice();
  infinite.origin_mm.x() = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(encode_message(StreamMessage{1, kScan, SliceUpdate{0, infinite}}).is_ok());
}

TEST(MeshStreamDecode, RejectsBadTopicsAndFrames) {
  const Frames good = encoded(mesh_message());
  expect_rejected({}, {"empty message"});
  for (const char* topic :
       {"meshes.2", "mesh.", "mesh.02", "mesh.0", "mesh.-1", "mesh.2x", "foo"}) {
    Frames frames = good;
    frames[0] = topic;
    expect_rejected(frames, {"unknown topic"});
  }
  expect_rejected(Frames{"status"}, {"status", "no header"});
  Frames not_json = good;
  not_json[1] = "{\"v\":1,";
  expect_rejected(not_json, {"mesh.2", "not valid JSON"});
  Frames not_object = good;
  not_object[1] = "[1, 2]";
  expect_rejected(not_object, {"not a JSON object"});
  Frames extra = encoded(StreamMessage{3, kScan, sample_status()});
  extra.emplace_back("x");
  expect_rejected(extra, {"status seq 3", "3 frames"});
  Frames missing_indices = good;
  missing_indices.pop_back();
  expect_rejected(missing_indices, {"3 frames"});
}

TEST(MeshStreamDecode, RejectsUnknownVersions) {
  const Frames good = encoded(mesh_message());
  for (const json& v : {json(2), json(0), json("1"), json(1.5)})
    expect_rejected(with_header(good, [&](json& h) { h["v"] = v; }), {"unknown format version"});
  expect_rejected(with_header(good, [](json& h) { h.erase("v"); }), {"\"v\" is missing"});
  const Frames status = encoded(StreamMessage{3, kScan, sample_status()});
  expect_rejected(with_header(status, [](json& h) { h["v"] = 2; }), {"status", "version"});
}

TEST(MeshStreamDecode, RejectsMissingFields) {
  const Frames mesh = encoded(mesh_message());
  for (const char* key : {"seq", "scan", "label", "name", "units", "frame", "timestamp_s", "slices",
                          "vertex_count", "triangle_count", "bounds"})
    expect_rejected(with_header(mesh, [&](json& h) { h.erase(key); }),
                    {"mesh.2", std::string("\"") + key + "\" is missing"});
  const Frames status = encoded(StreamMessage{3, kScan, sample_status()});
  for (const char* key :
       {"seq", "scan", "frames_received", "frames_dropped", "slices", "arrangement_ms", "field_ms",
        "smoothing_ms", "mesh_ms", "total_ms", "state"})
    expect_rejected(with_header(status, [&](json& h) { h.erase(key); }),
                    {"status", std::string("\"") + key + "\" is missing"});
  const Frames slice = encoded(StreamMessage{5, kScan, SliceUpdate{2, sample_slice()}});
  for (const char* key : {"v", "seq", "scan", "index", "plane"})
    expect_rejected(with_header(slice, [&](json& h) { h.erase(key); }),
                    {"slice", std::string("\"") + key + "\" is missing"});
  for (const char* key : {"origin", "u", "v"})
    expect_rejected(with_header(slice, [&](json& h) { h["plane"].erase(key); }),
                    {"slice", std::string("\"plane\" ") + key + " is missing"});
  expect_rejected(Frames{"end", "{}"}, {"end", "\"seq\" is missing"});
}

TEST(MeshStreamDecode, RejectsMistypedFields) {
  const Frames mesh = encoded(mesh_message());
  expect_rejected(with_header(mesh, [](json& h) { h["seq"] = -3; }),
                  {"\"seq\" must be an integer"});
  expect_rejected(with_header(mesh, [](json& h) { h["seq"] = 0; }), {"seq 0"});
  expect_rejected(with_header(mesh, [](json& h) { h["scan"] = ""; }), {"\"scan\" is empty"});
  expect_rejected(with_header(mesh, [](json& h) { h["name"] = 5; }), {"\"name\" must be a string"});
  expect_rejected(with_header(mesh, [](json& h) { h["timestamp_s"] = "soon"; }),
                  {"\"timestamp_s\" must be a finite number"});
  expect_rejected(with_header(mesh, [](json& h) { h["label"] = 3; }),
                  {"\"label\" is 3 but the topic names label 2"});
  expect_rejected(with_header(mesh, [](json& h) { h["normals"] = "yes"; }),
                  {"\"normals\" must be true or false"});
  const Frames status = encoded(StreamMessage{3, kScan, sample_status()});
  expect_rejected(with_header(status, [](json& h) { h["state"] = "paused"; }),
                  {"unknown \"state\" \"paused\""});
  expect_rejected(with_header(status, [](json& h) { h["state"] = "error"; }),
                  {"without a \"message\""});
  expect_rejected(with_header(status, [](json& h) { h["field_ms"] = -1.0; }),
                  {"\"field_ms\" is negative"});
  expect_rejected(with_header(status, [](json& h) { h["frames_dropped"] = 1.5; }),
                  {"\"frames_dropped\" must be an integer"});
}

TEST(MeshStreamDecode, RejectsCountsThatDisagreeWithFrameSizes) {
  const Frames good = encoded(mesh_message(11));
  expect_rejected(with_header(good, [](json& h) { h["vertex_count"] = 5; }),
                  {"mesh.2 seq 11", "frame 2 holds 48 bytes but vertex_count 5 needs 60"});
  expect_rejected(with_header(good, [](json& h) { h["triangle_count"] = 3; }),
                  {"frame 3 holds 48 bytes but triangle_count 3 needs 36"});
  Frames ragged = good;
  ragged[2].pop_back();
  expect_rejected(ragged, {"frame 2 holds 47 bytes"});
  expect_rejected(with_header(good, [](json& h) { h["normals"] = true; }),
                  {"4 frames", "\"normals\": true"});
  StreamMessage with_normals = mesh_message();
  std::get<MeshUpdate>(with_normals.body).normals = std::vector<Vec3>(4, Vec3(1, 0, 0));
  Frames short_normals = encoded(with_normals);
  short_normals[4].resize(36);
  expect_rejected(short_normals, {"frame 4 holds 36 bytes"});
  expect_rejected(with_header(good, [](json& h) { h["vertex_count"] = 1ull << 62; }),
                  {"vertex_count"});
}

TEST(MeshStreamDecode, RejectsIndicesOutOfRangeAndBadNumbers) {
  Frames bad_index = encoded(mesh_message());
  put_u32(bad_index[3], 7, 4);
  expect_rejected(bad_index, {"triangle 2 uses vertex index 4, out of range for vertex_count 4"});
  Frames nan = encoded(mesh_message());
  put_float(nan[2], 4, std::nanf(""));
  expect_rejected(nan, {"vertex 1 is NaN or infinite"});
  Frames outside = encoded(mesh_message());
  put_float(outside[2], 0, 50.0f);
  expect_rejected(outside, {"vertex 0 lies outside \"bounds\""});
  const Frames good = encoded(mesh_message());
  expect_rejected(with_header(good, [](json& h) { h["bounds"] = nullptr; }),
                  {"\"bounds\" is null but the mesh has vertices"});
  expect_rejected(with_header(good,
                              [](json& h) {
                                h["bounds"]["min"] = {0, 0};
                              }),
                  {"\"bounds\" min must be [x, y, z]"});
}

// Issue 27: an empty mesh that claims a box, and seqs no counter from 1 reaches (a snapshot
// `end` with seq 2^64-1 made a late joiner drop every later message as covered, silently).
TEST(MeshStreamDecode, RejectsAnEmptyMeshWithBounds) {
  StreamMessage message = mesh_message();
  std::get<MeshUpdate>(message.body).mesh = TriangleMesh{};
  const Frames empty = encoded(message);
  expect_rejected(with_header(empty,
                              [](json& h) {
                                h["bounds"] = {{"min", {0, 0, 0}}, {"max", {1, 1, 1}}};
                              }),
                  {"but the mesh is empty", "\"bounds\": null"});
}

TEST(MeshStreamDecode, RejectsSeqsAbove2To53) {
  const std::string max = std::to_string(std::numeric_limits<std::uint64_t>::max());
  expect_rejected(Frames{"end", "{\"seq\": " + max + "}"}, {"seq " + max, "above 2^53 - 1"});
  expect_rejected(
      with_header(encoded(mesh_message()), [](json& h) { h["seq"] = std::uint64_t{1} << 53; }),
      {"above 2^53 - 1"});
  // The largest accepted seq.
  Result<StreamMessage> edge = decode_message(
      Frames{"end", "{\"seq\": " + std::to_string((std::uint64_t{1} << 53) - 1) + "}"});
  EXPECT_TRUE(edge.is_ok()) << edge.message();
}

TEST(MeshStreamDecode, RejectsInvalidSlices) {
  const Frames good = encoded(StreamMessage{5, kScan, SliceUpdate{2, sample_slice()}});
  expect_rejected(with_header(good,
                              [](json& h) {
                                h["plane"]["u"] = {0, 2, 0};
                              }),
                  {"slice seq 5", "u is not unit length"});
  expect_rejected(with_header(good,
                              [](json& h) {
                                h["v"] = json::array({0, 0, 1});
                              }),
                  {"slice", "unknown format version"});
  expect_rejected(with_header(good, [](json& h) { h["plane"] = "xy"; }),
                  {"slice seq 5", "\"plane\" must be"});
  expect_rejected(with_header(good,
                              [](json& h) {
                                h["regions"][0]["polygon"] = {{0, 0}, {5, 0}, {10, 0}};
                              }),
                  {"slice seq 5", "zero area"});
  expect_rejected(with_header(good, [](json& h) { h["regions"][0]["label"] = 0; }), {"label 0"});
  expect_rejected(with_header(good, [](json& h) { h["index"] = "first"; }),
                  {"\"index\" must be an integer"});
}

TEST(MeshStreamDecode, IgnoresKeysItDoesNotKnow) {
  const Frames good = encoded(mesh_message());
  Result<StreamMessage> decoded =
      decode_message(with_header(good, [](json& h) { h["colour"] = "red"; }));
  EXPECT_TRUE(decoded.is_ok()) << decoded.message();
}

}  // namespace
}  // namespace sonoshape::publish::mesh_stream_test
