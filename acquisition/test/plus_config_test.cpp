#include "sonoshape/acquisition/plus_config.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/LU>
#include <filesystem>
#include <fstream>
#include <string>

namespace sonoshape::acquisition::plus_config_test {
namespace {

const std::filesystem::path kRealConfig =
    std::filesystem::path(SONOSHAPE_DATA_DIR) / "plus" /
    "PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml";

TEST(PlusConfig, RealConfigurationGivesImageToProbe) {
  const auto image_to_probe = read_image_to_probe(kRealConfig);
  ASSERT_TRUE(image_to_probe) << image_to_probe.message();
  EXPECT_DOUBLE_EQ((*image_to_probe)(0, 0), -0.00157821);
  EXPECT_DOUBLE_EQ((*image_to_probe)(0, 3), 15.3978);
  EXPECT_DOUBLE_EQ((*image_to_probe)(1, 3), 49.5705);
  EXPECT_DOUBLE_EQ((*image_to_probe)(2, 3), -8.63446);
  // About 0.085 mm per pixel: the calibration includes the pixel spacing.
  const double spacing_mm = image_to_probe->block<3, 1>(0, 0).norm();
  EXPECT_NEAR(spacing_mm, 0.085, 0.002);

  const auto config = read_plus_config(kRealConfig);
  ASSERT_TRUE(config);
  ASSERT_EQ(config->transforms.size(), 2u);
  EXPECT_EQ(config->transforms[1].from, "Phantom");
  EXPECT_NEAR(*config->transforms[0].error, 1.68149, 1e-12);
  const auto reference_to_phantom = config->transform("Reference", "Phantom");
  ASSERT_TRUE(reference_to_phantom);
  EXPECT_TRUE((*reference_to_phantom * *config->transform("Phantom", "Reference"))
                  .isApprox(Eigen::Matrix4d::Identity(), 1e-12));
  const auto missing = config->transform("Stylus", "Probe");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("ImageToProbe"), std::string::npos) << missing.message();
}

TEST(PlusConfig, WrittenConfigurationReadsBack) {
  PlusConfig config;
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<3, 3>(0, 0) *= 0.123456789012345;
  m(0, 3) = -31.25;
  config.transforms.push_back({"Image", "Probe", m, 0.5, "today"});
  const auto path = std::filesystem::temp_directory_path() /
                    ("sonoshape_plus_config_test_" + std::to_string(::getpid()) + ".xml");
  ASSERT_TRUE(write_plus_config(config, path, "simulated probe"));
  const auto reread = read_image_to_probe(path);
  ASSERT_TRUE(reread) << reread.message();
  EXPECT_EQ(*reread, m);
}

TEST(PlusConfig, BrokenFilesGiveClearErrors) {
  const auto path = std::filesystem::temp_directory_path() /
                    ("sonoshape_plus_config_bad_" + std::to_string(::getpid()) + ".xml");
  {
    std::ofstream(path) << "<PlusConfiguration><CoordinateDefinitions>"
                           "<Transform From=\"Image\" To=\"Probe\" Matrix=\"1 2 3\"/>"
                           "</CoordinateDefinitions></PlusConfiguration>";
  }
  auto result = read_plus_config(path);
  ASSERT_FALSE(result);
  EXPECT_NE(result.message().find("16 numbers"), std::string::npos) << result.message();
  { std::ofstream(path) << "<PlusConfiguration><unclosed></PlusConfiguration>"; }
  result = read_plus_config(path);
  ASSERT_FALSE(result);
  EXPECT_NE(result.message().find("at byte"), std::string::npos) << result.message();
  { std::ofstream(path) << "<Other/>"; }
  result = read_plus_config(path);
  ASSERT_FALSE(result);
  EXPECT_NE(result.message().find("PlusConfiguration"), std::string::npos) << result.message();
}

// Two definitions of one transform: equal ones are one definition; different ones (directly or
// as the inverse) are an error naming both, not the first one taken (issue 27).
TEST(PlusConfig, ConflictingDefinitionsOfATransformAreRefused) {
  Eigen::Matrix4d a = Eigen::Matrix4d::Identity();
  a.block<3, 3>(0, 0) *= 0.2;
  Eigen::Matrix4d b = a;
  b(0, 3) = 5.0;
  PlusConfig same;
  same.transforms = {{"Image", "Probe", a, 0.0, ""}, {"Image", "Probe", a, 0.0, ""}};
  const auto ok = same.transform("Image", "Probe");
  ASSERT_TRUE(ok) << ok.message();
  EXPECT_EQ(*ok, a);
  PlusConfig direct;
  direct.transforms = {{"Image", "Probe", a, 0.0, ""}, {"Image", "Probe", b, 0.0, ""}};
  auto refused = direct.transform("Image", "Probe");
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.message().find("defines ImageToProbe twice"), std::string::npos)
      << refused.message();
  PlusConfig inverse;
  inverse.transforms = {{"Image", "Probe", a, 0.0, ""},
                        {"Probe", "Image", Eigen::Matrix4d(b.inverse()), 0.0, ""}};
  refused = inverse.transform("Image", "Probe");
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.message().find("<Transform From=\"Probe\" To=\"Image\">"), std::string::npos)
      << refused.message();
  // The inverse of the same matrix is the same definition.
  inverse.transforms[1].matrix = a.inverse();
  EXPECT_TRUE(inverse.transform("Image", "Probe"));
}

}  // namespace
}  // namespace sonoshape::acquisition::plus_config_test
