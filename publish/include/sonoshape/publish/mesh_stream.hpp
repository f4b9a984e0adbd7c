#pragma once
// The messages of the live mesh stream (docs/formats/mesh-stream.md) as values: building them,
// and checking and parsing received ones. No sockets here: publisher.hpp and subscriber.hpp move
// the frames, and any other transport or a file can carry them too.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "sonoshape/core/geometry.hpp"
#include "sonoshape/core/mesh.hpp"
#include "sonoshape/core/scan_state.hpp"
#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"

namespace sonoshape::publish {

/// The format version this code writes and the only one it reads (header key "v").
constexpr int kMeshStreamVersion = 1;

/// Topic prefix of mesh messages ("mesh.<label_id>").
constexpr std::string_view kMeshTopicPrefix = "mesh.";
/// Topic of slice messages.
constexpr std::string_view kSliceTopic = "slice";
/// Topic of status messages.
constexpr std::string_view kStatusTopic = "status";
/// Topic of the last message of a snapshot reply.
constexpr std::string_view kEndTopic = "end";
/// Topic of the reply to a request the snapshot server does not know.
constexpr std::string_view kErrorTopic = "error";
/// The one-frame request a snapshot server answers (8 ASCII bytes, no terminator).
constexpr std::string_view kSnapshotRequest = "snapshot";

/// One multipart message: frame 0 the topic, frame 1 the JSON header, then binary frames.
using Frames = std::vector<std::string>;

/// What the scan is doing, as a status message says it (one enum with the scan pipeline).
using sonoshape::ScanState;
using sonoshape::to_string;

/// Body of a `mesh.<label>` message: the whole current surface of one material.
struct MeshUpdate {
  int label = 1;                             ///< material id, >= 1
  std::string name;                          ///< material name ("" when the slices name none)
  std::string units = "mm";                  ///< unit of every position
  std::string frame = "reference";           ///< coordinate frame of the positions
  double timestamp_s = 0.0;                  ///< time of the newest slice the surface includes
  std::uint64_t slices = 0;                  ///< how many slices the surface was built from
  TriangleMesh mesh;                         ///< sent as float32 positions and uint32 indices
  std::optional<std::vector<Vec3>> normals;  ///< per-vertex unit normals, sent when present
  /// Box of the positions. Ignored when encoding (computed from the float32 positions); set by
  /// decoding, none for an empty mesh.
  std::optional<Box3> bounds;
};

/// Body of a `slice` message: the slice just added to the reconstruction.
struct SliceUpdate {
  std::uint64_t index = 0;  ///< position of the slice in the scan, from 0
  LabeledSlice slice;
};

/// Body of a `status` message: counters and the stage times of the last update.
struct StatusReport {
  std::uint64_t frames_received = 0;
  std::uint64_t frames_dropped = 0;
  std::uint64_t slices = 0;
  double arrangement_ms = 0.0;
  double field_ms = 0.0;
  double smoothing_ms = 0.0;
  double mesh_ms = 0.0;
  double total_ms = 0.0;
  ScanState state = ScanState::kScanning;
  std::string message;  ///< what went wrong; required (non-empty) when state is kError
};

/// Body of the `end` message that closes a snapshot reply; its seq is the newest seq published.
struct SnapshotEnd {};

/// A whole message: the fields every header carries and one of the bodies.
struct StreamMessage {
  std::uint64_t seq = 0;  ///< from 1, one counter across topics; `end` may carry 0 (nothing yet)
  std::string scan;       ///< uuid of the scan
  std::variant<MeshUpdate, SliceUpdate, StatusReport, SnapshotEnd> body;

  /// The topic of the body: "mesh.<label>", "slice", "status" or "end".
  std::string topic() const;
};

/// Builds the frames of a message. Fails (nothing built) when the message cannot be sent as the
/// format says: NaN or infinite numbers, a label below 1, a triangle index out of range, more than
/// 2^32-1 vertices or triangles, normals not one per vertex, an error state without a message, an
/// empty scan uuid, or seq 0 outside `end`.
Result<Frames> encode_message(const StreamMessage& message);

/// Checks received frames against the format and parses them. The error names the topic and seq
/// when known and what is wrong: an empty or unknown topic, a wrong frame count, a header that is
/// not a JSON object, a missing or mistyped field, an unknown `v`, counts that disagree with the
/// frame sizes, an index out of range, non-finite numbers, bounds that do not hold the positions,
/// an invalid slice (slices.md rules), an unknown state. Keys the format does not name are ignored.
Result<StreamMessage> decode_message(const Frames& frames);

}  // namespace sonoshape::publish
