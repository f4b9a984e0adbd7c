#pragma once
// A small simulated sweep for segmentation tests: a 12 mm sphere (label 1, "organ") with a 5 mm
// sphere beside it (label 2, "lesion"), seen by a 160 px linear probe sliding 8 mm.
#include <Eigen/Geometry>

#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"
#include "sonoshape/simulator/sweep.hpp"
#include "sonoshape/simulator/trajectory.hpp"

namespace sonoshape::segmentation::test {

/// The probe's motion with its tracked poses, and the frames rendered from it.
struct SmallSweep {
  simulator::SimulatedAcquisition acquisition;
  simulator::SimulatedSweep sweep;
};

/// `frames` frames at 20 Hz with the tracker `tracker` (speckle seed 3).
inline SmallSweep organ_and_lesion_sweep(int frames,
                                         const simulator::TrackerOptions& tracker = {}) {
  simulator::Phantom phantom;
  Eigen::Affine3d place = Eigen::Affine3d::Identity();
  place.translation() = Vec3(-5, 25, 0);
  phantom.add(1, "organ", simulator::make_sphere(12.0), place);
  place.translation() = Vec3(12, 15, 0);
  phantom.add(2, "lesion", simulator::make_sphere(5.0), place);
  const acquisition::Probe probe(acquisition::linear_probe_geometry(160, 160));
  const simulator::BModeSimulator simulator(phantom, probe);
  simulator::TrajectoryOptions motion;
  motion.duration_s = 0.45;
  motion.sweep_length_mm = 8.0;
  SmallSweep out;
  out.acquisition = simulator::acquire(simulator::Trajectory(motion), tracker, frames, 20.0);
  out.sweep = simulator::simulate_sweep(simulator, out.acquisition, 3);
  return out;
}

}  // namespace sonoshape::segmentation::test
