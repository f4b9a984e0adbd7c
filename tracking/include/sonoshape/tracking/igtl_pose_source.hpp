#pragma once
// `--source igtl:HOST:PORT`, poses: TRANSFORM messages of an OpenIGTLink server (PlusServer's
// ProbeToReference / ProbeToTracker), or the pose an IMAGE message carries. Built only with
// SONOSHAPE_WITH_OPENIGTLINK.
#include <map>
#include <optional>
#include <string>

#include "sonoshape/acquisition/igtl_client.hpp"
#include "sonoshape/tracking/pose_source.hpp"

namespace sonoshape::tracking {

/// Which message carries the probe pose.
enum class IgtlPoseFrom {
  kTransform,     ///< TRANSFORM messages named so: the matrix is T_reference_probe
  kTrackingData,  ///< the element so named of TDATA messages (streaming asked for on connection)
  kImage,         ///< IMAGE messages named so ("": any): the image's own pose; the probe frame is
                  ///< then the image's, in mm, at pixel (0, 0) (calibration: the pixel spacing)
};

/// Receives tracker samples from an OpenIGTLink server over a connection of its own (a
/// PlusServer serves every client the same stream). Pose::timestamp_s is the message's
/// timestamp. A matrix that is not finite or not rigid (rotation part off by more than 1e-3)
/// is an INVALID sample, never used as a pose. A server that goes away after the first
/// connection is the source's condition() while it is connected to again (acquisition::IgtlLink).
/// Messages that cannot be read (a bad CRC, a body of the wrong size) are dropped and counted
/// in losses() by reason, the first of each logged.
class IgtlPoses final : public PoseBackend {
 public:
  IgtlPoses(acquisition::IgtlEndpoint endpoint, std::string device, IgtlPoseFrom from);

  std::string describe() const override;
  std::map<std::string, std::size_t> losses() const override { return drops_.counts(); }

 protected:
  Status open() override;
  Result<acquisition::Polled> poll(Pose& pose) override;
  void close() override { link_.close(); }

 private:
  std::string device_;
  IgtlPoseFrom from_;
  acquisition::IgtlLink link_;
  acquisition::IgtlDrops drops_;
};
/// The stream of an IgtlPoses.
using IgtlPoseSource = acquisition::SourceOf<IgtlPoses>;

/// A sample from a matrix: rigid within 1e-3 -> valid, else kInvalid (identity pose).
Pose pose_from_matrix(const Eigen::Matrix4d& T_reference_probe, double timestamp_s);

}  // namespace sonoshape::tracking
