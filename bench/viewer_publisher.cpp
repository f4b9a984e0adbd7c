// Publishes synthetic surfaces on a mesh stream for the browser view's benchmark
// (bench/viewer_bench.mjs, docs/benchmarks.md "Browser view"): three labels of about N triangles
// each (spheres side by side), one update every interval. Each update's `timestamp_s` is the wall
// clock (Unix seconds) when it is handed to the publisher, so that a page on this machine can
// tell how long the mesh took from published to drawn.
//
// sonoshape_viewer_publisher ENDPOINT TRIANGLES UPDATES INTERVAL_MS [START_DELAY_MS]
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <numbers>
#include <string>
#include <thread>

#include "sonoshape/publish/publisher.hpp"

using namespace sonoshape;

namespace {

// A UV sphere of about `triangles` triangles (outward), radius r mm, centred at `centre`.
TriangleMesh sphere(std::size_t triangles, double radius_mm, const Vec3& centre) {
  const int rings = std::max(3, static_cast<int>(std::sqrt(triangles / 2.0)));
  const int sectors = rings;
  TriangleMesh mesh;
  for (int i = 0; i <= rings; ++i) {
    const double theta = std::numbers::pi * i / rings;
    for (int j = 0; j < sectors; ++j) {
      const double phi = 2 * std::numbers::pi * j / sectors;
      mesh.vertices.push_back(centre + radius_mm * Vec3(std::sin(theta) * std::cos(phi),
                                                        std::sin(theta) * std::sin(phi),
                                                        std::cos(theta)));
    }
  }
  const auto at = [&](int i, int j) {
    return static_cast<std::uint32_t>(i * sectors + j % sectors);
  };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sectors; ++j) {
      mesh.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return mesh;
}

double unix_seconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5) {
    std::cerr << "usage: sonoshape_viewer_publisher ENDPOINT TRIANGLES UPDATES INTERVAL_MS "
                 "[START_DELAY_MS]\n";
    return 2;
  }
  publish::PublisherOptions options;
  options.endpoint = argv[1];
  const auto triangles = static_cast<std::size_t>(std::atoll(argv[2]));
  const int updates = std::atoi(argv[3]);
  const int interval_ms = std::atoi(argv[4]);
  const int delay_ms = argc > 5 ? std::atoi(argv[5]) : 1000;
  Result<publish::MeshPublisher> publisher = publish::MeshPublisher::bind(options);
  if (!publisher) {
    std::cerr << "error: " << publisher.message() << '\n';
    return 1;
  }
  MeshSet meshes;
  for (int label = 1; label <= 3; ++label)
    meshes.meshes.push_back({label, "sphere " + std::to_string(label),
                             sphere(triangles, 30.0, Vec3(70.0 * (label - 2), 0, 0))});
  std::cout << "publishing on " << publisher->endpoint() << ": 3 labels of "
            << meshes.meshes[0].mesh.triangles.size() << " triangles" << std::endl;
  // Time for subscribers (the view) to connect: PUB sends nothing to those not yet there.
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  for (int k = 1; k <= updates; ++k) {
    // Move the spheres a little: every update is a new surface.
    for (auto& entry : meshes.meshes)
      for (Vec3& v : entry.mesh.vertices) v.z() += 0.01;
    if (Status sent = publisher->publish_meshes(meshes, unix_seconds(), k); !sent) {
      std::cerr << "error: " << sent.message() << '\n';
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(interval_ms));
  }
  publish::StatusReport idle;
  idle.state = ScanState::kIdle;
  (void)publisher->publish_status(idle);
  std::cout << "published " << updates << " updates" << std::endl;
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  return 0;
}
