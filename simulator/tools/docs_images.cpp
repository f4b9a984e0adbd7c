// Writes the simulator pictures of docs/: a B-mode frame beside its ground truth for a linear and
// a convex probe (docs/images/sim_linear.png, sim_convex.png). Run from anywhere:
//   cmake --build build --target sonoshape_docs_images && build/simulator/sonoshape_docs_images
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sonoshape/core/png_file.hpp"
#include "sonoshape/simulator/bmode.hpp"
#include "sonoshape/simulator/phantom.hpp"

namespace {

using namespace sonoshape;

// Label colours (BGR): background dark grey, labels distinct, unknown a hatched magenta-ish.
cv::Vec3b label_colour(std::uint8_t label) {
  switch (label) {
    case kLabelPixelOutside:
      return {40, 40, 40};
    case 1:
      return {60, 160, 230};
    case 2:
      return {90, 200, 90};
    case 3:
      return {230, 230, 230};
    case kLabelPixelUnknown:
      return {0, 0, 0};
    default:
      return {200, 100, 200};
  }
}

cv::Mat side_by_side(const simulator::SimulatedFrame& frame) {
  const int w = frame.bmode.width, h = frame.bmode.height;
  cv::Mat out(h, 2 * w + 8, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const std::uint8_t g = frame.bmode.at(i, j);
      out.at<cv::Vec3b>(j, i) = cv::Vec3b(g, g, g);
      const std::uint8_t t = frame.truth.at(i, j);
      cv::Vec3b colour = label_colour(t);
      // Shadowed (unknown inside the sector): hatched, so it reads apart from "outside".
      if (t == kLabelPixelUnknown && frame.labels.at(i, j) != kLabelPixelUnknown)
        colour = ((i + j) / 4) % 2 ? cv::Vec3b(120, 40, 160) : cv::Vec3b(60, 20, 80);
      out.at<cv::Vec3b>(j, w + 8 + i) = colour;
    }
  return out;
}

Eigen::Isometry3d probe_above(const Box3& box, double standoff_mm, double z_mm, double x_mm) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Vec3(x_mm, box.min.y() - standoff_mm, z_mm);
  return T;
}

}  // namespace

int main(int argc, char** argv) {
  const std::filesystem::path source = SONOSHAPE_SOURCE_DIR;
  const std::filesystem::path out_dir = argc > 1 ? argv[1] : source / "docs" / "images";
  std::filesystem::create_directories(out_dir);
  struct Shot {
    const char* file;
    acquisition::ProbeGeometry probe;
    double size_mm, standoff_mm, z_fraction, x_mm;
  };
  const Shot shots[] = {
      {"sim_convex.png", acquisition::convex_probe_geometry(512, 512), 120.0, 12.0, 0.45, 0.0},
      {"sim_linear.png", acquisition::linear_probe_geometry(512, 512), 60.0, 4.0, 0.45, -6.0},
  };
  for (const Shot& shot : shots) {
    auto phantom = simulator::make_default_phantom(source / "data" / "models", shot.size_mm);
    if (!phantom) {
      std::cerr << "error: " << phantom.message() << '\n';
      return 1;
    }
    const Box3 box = phantom->bounds();
    const simulator::BModeSimulator simulator(*phantom, acquisition::Probe(shot.probe));
    const double z = box.min.z() + shot.z_fraction * box.size().z();
    const auto frame = simulator.render(probe_above(box, shot.standoff_mm, z, shot.x_mm), 7);
    const auto path = out_dir / shot.file;
    const cv::Mat picture = side_by_side(frame);
    if (const Status written = write_png(path, PngPixels::kBgr, picture.cols, picture.rows,
                                         picture.data, static_cast<std::ptrdiff_t>(picture.step));
        !written) {
      std::cerr << "error: " << written.message() << '\n';
      return 1;
    }
    std::cout << "wrote " << path.string() << " (shadowed " << 100.0 * frame.shadow_fraction
              << "% of the sector)\n";
  }
  return 0;
}
