#include "sonoshape/tracking/igtl_pose_source.hpp"

namespace sonoshape::tracking {

IgtlPoses::IgtlPoses(acquisition::IgtlEndpoint endpoint, std::string device, IgtlPoseFrom from)
    : device_(std::move(device)),
      from_(from),
      // TDATA streams only on request, on every connection; every 20 ms (50 Hz) is as fast as
      // trackers usually go.
      link_(std::move(endpoint),
            from == IgtlPoseFrom::kTrackingData
                ? acquisition::IgtlLink::OnConnect([](acquisition::IgtlConnection& connection) {
                    return connection.send(acquisition::igtl_start_tracking_data(20));
                  })
                : acquisition::IgtlLink::OnConnect()),
      drops_("igtl:" + link_.endpoint().text()) {}

std::string IgtlPoses::describe() const {
  return "igtl:" + link_.endpoint().text() +
         (from_ == IgtlPoseFrom::kTransform ? " (TRANSFORM " + device_ + ")" : " (IMAGE poses)");
}

Status IgtlPoses::open() { return link_.open(); }

Pose pose_from_matrix(const Eigen::Matrix4d& T, double timestamp_s) {
  Pose pose;
  pose.timestamp_s = timestamp_s;
  const Eigen::Matrix3d R = T.block<3, 3>(0, 0);
  if (!T.allFinite() ||
      (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 ||
      R.determinant() < 0.0) {
    pose.status = TrackingStatus::kInvalid;
    return pose;
  }
  pose.T_reference_probe.linear() = R;
  pose.T_reference_probe.translation() = T.block<3, 1>(0, 3);
  return pose;
}

Result<acquisition::Polled> IgtlPoses::poll(Pose& pose) {
  const std::optional<acquisition::IgtlMessage> message = link_.next(0.1);
  set_condition(link_.trouble());
  if (!message) return acquisition::Polled::kNothing;
  const acquisition::IgtlMessage& m = *message;
  const bool named = device_.empty() || m.device == device_;
  if (from_ == IgtlPoseFrom::kTransform && m.type == "TRANSFORM" && named) {
    auto T = acquisition::decode_igtl_transform(m);
    if (!T) {
      drops_.count(acquisition::IgtlDrop::kDamaged, T.message());
      count_lost(1);
      return acquisition::Polled::kNothing;
    }
    pose = pose_from_matrix(*T, m.timestamp_s);
    return acquisition::Polled::kItem;
  }
  if (from_ == IgtlPoseFrom::kTrackingData && m.type == "TDATA") {
    auto T = acquisition::decode_igtl_tracking_data(m, device_);
    if (!T) {
      drops_.count(acquisition::IgtlDrop::kDamaged, T.message());
      count_lost(1);
      return acquisition::Polled::kNothing;
    }
    if (!*T) return acquisition::Polled::kNothing;  // this tool is not in this message
    pose = pose_from_matrix(**T, m.timestamp_s);
    return acquisition::Polled::kItem;
  }
  if (from_ == IgtlPoseFrom::kImage && m.type == "IMAGE" && named) {
    acquisition::IgtlDrop why = acquisition::IgtlDrop::kDamaged;
    auto image = acquisition::decode_igtl_image(m, &why);
    if (!image) {
      drops_.count(why, image.message());
      count_lost(1);
      return acquisition::Polled::kNothing;
    }
    // The image frame in mm: the spacing divided out of the pixel axes.
    Eigen::Matrix4d T = image->T_reference_image;
    T.col(0).head<3>() /= image->spacing_mm[0];
    T.col(1).head<3>() /= image->spacing_mm[1];
    pose = pose_from_matrix(T, m.timestamp_s);
    return acquisition::Polled::kItem;
  }
  return acquisition::Polled::kNothing;
}

}  // namespace sonoshape::tracking
