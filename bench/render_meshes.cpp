// sonoshape_render: a quick-look picture of meshes (and the input contours), for docs and for
// checking a reconstruction by eye. Orthographic z-buffer rendering with Lambert shading.
//
//   sonoshape_render -o view.png [--view iso|x|y|z] [--size PIXELS] [--slices S.slices.json]
//                    MESH [MESH ...]
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "sonoshape/core/mesh_io.hpp"
#include "sonoshape/core/png_file.hpp"
#include "sonoshape/core/slice_io.hpp"

namespace {

using sonoshape::Vec3;

Eigen::Matrix3d view_rotation(const std::string& view) {
  const auto rot = [](const Vec3& axis, double degrees) {
    return Eigen::AngleAxisd(degrees * M_PI / 180.0, axis).toRotationMatrix();
  };
  if (view == "x") return rot(Vec3::UnitY(), -90.0) * rot(Vec3::UnitX(), -90.0);
  if (view == "y") return rot(Vec3::UnitX(), -90.0);
  if (view == "z") return Eigen::Matrix3d::Identity();
  return rot(Vec3::UnitX(), -60.0) * rot(Vec3::UnitZ(), -35.0);  // iso
}

}  // namespace

int main(int argc, char** argv) {
  std::string output = "view.png", view = "iso", slices_path;
  int size = 900;  // pixels, square
  std::vector<std::string> meshes;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-o" && i + 1 < argc)
      output = argv[++i];
    else if (a == "--view" && i + 1 < argc)
      view = argv[++i];
    else if (a == "--size" && i + 1 < argc)
      size = std::atoi(argv[++i]);
    else if (a == "--slices" && i + 1 < argc)
      slices_path = argv[++i];
    else
      meshes.push_back(a);
  }
  if (output.size() < 4 || output.compare(output.size() - 4, 4, ".png") != 0) {
    std::cerr << "error: -o " << output << ": the picture is written as PNG; name it *.png\n";
    return 2;
  }
  if (size < 16 || size > 8192) {
    std::cerr << "error: --size takes 16..8192 pixels\n";
    return 2;
  }
  if (meshes.empty()) {
    std::cerr
        << "usage: sonoshape_render -o view.png [--view iso|x|y|z] [--size PIXELS] [--slices S] "
           "MESH...\n";
    return 2;
  }
  const Eigen::Matrix3d rotation = view_rotation(view);
  std::vector<sonoshape::TriangleMesh> loaded;
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const std::string& path : meshes) {
    auto mesh = sonoshape::read_mesh(path);
    if (!mesh) {
      std::cerr << "error: " << mesh.message() << '\n';
      return 1;
    }
    for (Vec3& p : mesh->vertices) {
      p = rotation * p;
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    loaded.push_back(std::move(*mesh));
  }
  const double scale = 0.9 * size / std::max(hi.x() - lo.x(), hi.y() - lo.y());
  const Vec3 center = 0.5 * (lo + hi);
  auto to_image = [&](const Vec3& p) {
    return Eigen::Vector2d(0.5 * size + (p.x() - center.x()) * scale,
                           0.5 * size - (p.y() - center.y()) * scale);
  };
  cv::Mat image(size, size, CV_8UC3, cv::Scalar(255, 255, 255));
  std::vector<double> depth(static_cast<std::size_t>(size * size),
                            -std::numeric_limits<double>::infinity());
  const std::vector<cv::Vec3d> colours{
      {90, 150, 230}, {120, 200, 120}, {220, 160, 90}, {200, 120, 200}};
  const Vec3 light = Vec3(0.3, 0.5, 1.0).normalized();
  for (std::size_t m = 0; m < loaded.size(); ++m) {
    const auto& mesh = loaded[m];
    for (const auto& t : mesh.triangles) {
      const Vec3& a = mesh.vertices[t[0]];
      const Vec3& b = mesh.vertices[t[1]];
      const Vec3& c = mesh.vertices[t[2]];
      Vec3 n = (b - a).cross(c - a);
      if (n.norm() == 0.0) continue;
      n.normalize();
      const double shade = 0.25 + 0.75 * std::abs(n.dot(light));
      const Eigen::Vector2d pa = to_image(a), pb = to_image(b), pc = to_image(c);
      const int x0 = std::max(0, static_cast<int>(std::floor(std::min({pa.x(), pb.x(), pc.x()}))));
      const int x1 =
          std::min(size - 1, static_cast<int>(std::ceil(std::max({pa.x(), pb.x(), pc.x()}))));
      const int y0 = std::max(0, static_cast<int>(std::floor(std::min({pa.y(), pb.y(), pc.y()}))));
      const int y1 =
          std::min(size - 1, static_cast<int>(std::ceil(std::max({pa.y(), pb.y(), pc.y()}))));
      const double area = (pb - pa).x() * (pc - pa).y() - (pb - pa).y() * (pc - pa).x();
      if (area == 0.0) continue;
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const Eigen::Vector2d p(x + 0.5, y + 0.5);
          const double w0 = ((pb - p).x() * (pc - p).y() - (pb - p).y() * (pc - p).x()) / area;
          const double w1 = ((pc - p).x() * (pa - p).y() - (pc - p).y() * (pa - p).x()) / area;
          const double w2 = 1.0 - w0 - w1;
          if (w0 < 0 || w1 < 0 || w2 < 0) continue;
          const double z = w0 * a.z() + w1 * b.z() + w2 * c.z();
          double& d = depth[static_cast<std::size_t>(y * size + x)];
          if (z <= d) continue;
          d = z;
          const cv::Vec3d& colour = colours[m % colours.size()];
          image.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(colour[0] * shade),
                                                static_cast<uchar>(colour[1] * shade),
                                                static_cast<uchar>(colour[2] * shade));
        }
    }
  }
  if (!slices_path.empty()) {
    // Input contours in red on top (hidden or not), to see the surface pass through them.
    const auto set = sonoshape::read_slice_set(slices_path);
    if (!set) {
      std::cerr << "error: " << set.message() << '\n';
      return 1;
    }
    for (const auto& s : set->slices)
      for (const auto& r : s.regions) {
        if (r.label == sonoshape::kUnknownLabel) continue;
        auto draw = [&](const sonoshape::Ring2& ring) {
          for (std::size_t i = 0; i < ring.size(); ++i) {
            const Eigen::Vector2d p = to_image(rotation * s.to_world(ring[i]));
            const Eigen::Vector2d q = to_image(rotation * s.to_world(ring[(i + 1) % ring.size()]));
            cv::line(image, cv::Point2d(p.x(), p.y()), cv::Point2d(q.x(), q.y()),
                     cv::Scalar(30, 30, 200), 1, cv::LINE_AA);
          }
        };
        draw(r.outer);
        for (const auto& h : r.holes) draw(h);
      }
  }
  if (const sonoshape::Status written =
          sonoshape::write_png(output, sonoshape::PngPixels::kBgr, image.cols, image.rows,
                               image.data, static_cast<std::ptrdiff_t>(image.step));
      !written) {
    std::cerr << "error: " << written.message() << '\n';
    return 1;
  }
  std::cerr << "wrote " << output << '\n';
  return 0;
}
