#pragma once
// Families of cutting planes for building test slice sets.
#include <cstdint>
#include <string>
#include <vector>

#include "sonoshape/core/mesh_slicer.hpp"

namespace sonoshape::simulator {

enum class PlaneFamily { kParallel, kOrthogonal, kRandom, kSweep };

/// Parses "parallel" | "orthogonal" | "random" | "sweep"; throws std::invalid_argument otherwise.
PlaneFamily parse_plane_family(const std::string& name);

/// `count` planes that cut the box `object_box` (the objects' bounds): parallel (evenly spaced
/// along one axis), orthogonal (split over x, y, z), random (random orientation through random
/// interior points), sweep (a freehand-like sweep: slowly tilting planes moving across). Planes
/// are deterministic for a seed and never pass through the exact box centre lines.
std::vector<SlicePlane> generate_planes(PlaneFamily family, int count, const Box3& object_box,
                                        std::uint64_t seed);

}  // namespace sonoshape::simulator
