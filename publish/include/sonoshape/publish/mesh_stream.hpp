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
#include "sonoshape/core/image.hpp"
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
/// Topic of B-mode frame messages (an optional, downsampled grey picture of the current frame).
constexpr std::string_view kFrameTopic = "frame";
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

/// Where a plane lies: the world point of its in-plane (0, 0), and two unit, orthogonal
/// directions; the in-plane point (a, b) is origin_mm + a*u + b*v (slices.md).
struct PlaneFrame {
  Vec3 origin_mm = Vec3::Zero();
  Vec3 u = Vec3::UnitX();
  Vec3 v = Vec3::UnitY();
};

/// Body of a `frame` message: a B-mode frame as a small grey picture on its plane, for views.
/// The picture covers the rectangle a in [0, size_mm[0]], b in [0, size_mm[1]] of `plane`;
/// pixel (i, j) (row j from the transducer side, row-major) covers a in [i, i+1) * size_mm[0] /
/// width and b in [j, j+1) * size_mm[1] / height.
struct FrameImage {
  std::int64_t index = 0;       ///< the frame's position in its source, from 0
  double timestamp_s = 0.0;     ///< acquisition time (device clock)
  GreyImage image;              ///< 8-bit grey, width * height bytes; not empty
  PlaneFrame plane;             ///< origin at the outer corner of pixel (0, 0)
  Vec2 size_mm = Vec2::Zero();  ///< the picture's extent along u and v, both > 0
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
  /// Wall time of the last update and the frame-to-mesh latency of its newest slice (from the
  /// frame's arrival to its surfaces being ready), in ms; none before the first update.
  std::optional<double> update_ms;
  std::optional<double> latency_ms;
  ScanState state = ScanState::kScanning;
  std::string message;  ///< what went wrong; required (non-empty) when state is kError
  /// The scan's last status (`"finished": true`): nothing more comes, the counts are final and
  /// the newest meshes are the result. Only with state idle or error.
  bool finished = false;
  /// At most how many `frame` messages a second the scan publishes (`"frame_rate_hz"`; 0: none,
  /// so that a view says why it shows no B-mode frame); absent from older publishers.
  std::optional<double> frame_rate_hz;
};

/// Body of the `end` message that closes a snapshot reply; its seq is the newest seq published.
struct SnapshotEnd {};

/// A whole message: the fields every header carries and one of the bodies.
struct StreamMessage {
  std::uint64_t seq = 0;  ///< from 1, one counter across topics; `end` may carry 0 (nothing yet)
  std::string scan;       ///< uuid of the scan
  std::variant<MeshUpdate, SliceUpdate, StatusReport, FrameImage, SnapshotEnd> body;

  /// The topic of the body: "mesh.<label>", "slice", "status", "frame" or "end".
  std::string topic() const;
};

/// The most mesh labels of one scan that a subscriber keeps (the view, `listen`): segmentation
/// labels fit in a byte, so a stream with more is broken or hostile; the meshes of further labels
/// are dropped and counted, so that many labels cannot stall a subscriber or fill its disk.
constexpr int kMaxStreamLabels = 256;

/// The largest side (pixels) of a `frame` message's picture: it is a preview, not the data.
constexpr int kMaxFrameImageSide = 1024;

/// Builds the frames of a message. Fails (nothing built) when the message cannot be sent as the
/// format says: NaN or infinite numbers, a label below 1, a triangle index out of range, more than
/// 2^32-1 vertices or triangles, normals not one per vertex, an error state without a message, an
/// empty scan uuid, seq 0 outside `end`, or a frame image that is empty, larger than
/// kMaxFrameImageSide on a side, has pixels not width * height, or a size or plane that is not
/// positive and orthonormal.
Result<Frames> encode_message(const StreamMessage& message);

/// Checks received frames against the format and parses them. The error names the topic and seq
/// when known and what is wrong: an empty or unknown topic, a wrong frame count, a header that is
/// not a JSON object, a missing or mistyped field, an unknown `v`, counts that disagree with the
/// frame sizes, an index out of range, non-finite numbers, bounds that do not hold the positions,
/// an invalid slice (slices.md rules), an unknown state. Keys the format does not name are ignored.
Result<StreamMessage> decode_message(const Frames& frames);

}  // namespace sonoshape::publish
