#include "sonoshape/acquisition/sequence_file.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>
#include <string>

namespace sonoshape::acquisition::sequence_file_test {
namespace {

const std::filesystem::path kRealFile =
    std::filesystem::path(SONOSHAPE_DATA_DIR) / "plus" / "SpinePhantomFreehand.igs.mha";

std::filesystem::path temp_path(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("sonoshape_acquisition_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir / name;
}

std::uint64_t pixel_sum(const GreyImage& image) {
  return std::accumulate(image.pixels.begin(), image.pixels.end(), std::uint64_t{0});
}

TEST(SequenceFile, RealPlusFileLoadsWithFramesTimestampsAndTransforms) {
  const auto file = read_sequence_file(kRealFile);
  ASSERT_TRUE(file) << file.message();
  EXPECT_EQ(file->width(), 820);
  EXPECT_EQ(file->height(), 616);
  ASSERT_EQ(file->frame_count(), 21u);
  EXPECT_EQ(file->field("UltrasoundImageOrientation"), "MFA");
  EXPECT_EQ(file->field("AnatomicalOrientation"), "RAI");
  EXPECT_EQ(file->field("CompressedDataSize"), "3466024");  // trailing padding trimmed

  // Numbers from the header text.
  EXPECT_DOUBLE_EQ(*file->timestamp_s(0), 215.102186);
  EXPECT_DOUBLE_EQ(*file->timestamp_s(20), 216.947186);
  EXPECT_DOUBLE_EQ(file->frame(1).timestamp_s, 215.190114);
  const auto probe0 = file->transform("ProbeToTracker", 0);
  ASSERT_TRUE(probe0) << probe0.message();
  EXPECT_DOUBLE_EQ((*probe0)(0, 0), 0.231245);
  EXPECT_DOUBLE_EQ((*probe0)(0, 3), 172.641);
  EXPECT_DOUBLE_EQ((*probe0)(1, 3), -98.0022);
  EXPECT_DOUBLE_EQ((*probe0)(3, 3), 1.0);
  const auto reference1 = file->transform("ReferenceToTracker", 1);
  ASSERT_TRUE(reference1);
  EXPECT_DOUBLE_EQ((*reference1)(1, 3), 93.985);
  EXPECT_EQ(file->transform_status("ProbeToTracker", 5), TrackingStatus::kValid);
  EXPECT_EQ(file->transform_names(),
            (std::vector<std::string>{"ProbeToTracker", "ReferenceToTracker", "StylusToTracker"}));
  EXPECT_EQ(file->frame_field(3, "ImageStatus"), "OK");

  // Pixels, checked against an independent zlib decode of the file.
  EXPECT_EQ(pixel_sum(file->image(0)), 18036414u);
  EXPECT_EQ(pixel_sum(file->image(20)), 17810681u);
  EXPECT_EQ(file->image(0).at(400, 300), 2);
  EXPECT_EQ(file->image(20).at(410, 100), 200);

  const auto missing = file->transform("NeedleToTracker", 0);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("ProbeToTracker"), std::string::npos) << missing.message();
}

void expect_same(const SequenceFile& a, const SequenceFile& b) {
  ASSERT_EQ(a.width(), b.width());
  ASSERT_EQ(a.height(), b.height());
  ASSERT_EQ(a.frame_count(), b.frame_count());
  for (std::size_t k = 0; k < a.frame_count(); ++k) {
    EXPECT_EQ(a.image(k), b.image(k)) << "frame " << k;
    EXPECT_EQ(a.frame_fields(k), b.frame_fields(k)) << "frame " << k;
  }
  // Every global field that does not describe the pixel layout is kept, in order.
  auto non_layout = [](const FieldList& fields) {
    FieldList out;
    for (const auto& f : fields)
      if (f.first != "NDims" && f.first != "DimSize" && f.first != "CompressedData" &&
          f.first != "CompressedDataSize" && f.first != "ElementType" && f.first != "BinaryData" &&
          f.first != "BinaryDataByteOrderMSB" && f.first != "ElementDataFile" &&
          f.first != "ObjectType")
        out.push_back(f);
    return out;
  };
  EXPECT_EQ(non_layout(a.fields()), non_layout(b.fields()));
}

TEST(SequenceFile, RealFileRoundTripsCompressedAndRaw) {
  const auto original = read_sequence_file(kRealFile);
  ASSERT_TRUE(original) << original.message();
  for (const bool compress : {true, false}) {
    const auto path = temp_path(compress ? "real_compressed.igs.mha" : "real_raw.igs.mha");
    ASSERT_TRUE(write_sequence_file(*original, path, {compress, 6}));
    const auto reread = read_sequence_file(path);
    ASSERT_TRUE(reread) << reread.message();
    expect_same(*original, *reread);
    EXPECT_EQ(reread->field("CompressedData"), compress ? "True" : "False");
    // Unchanged fields keep their exact text (and a re-read of the rewrite is identical).
    EXPECT_EQ(reread->frame_field(7, "StylusToTrackerTransform"),
              original->frame_field(7, "StylusToTrackerTransform"));
  }
}

SequenceFile synthetic(int frames) {
  SequenceFile file;
  file.set_field("UltrasoundImageOrientation", "MF");
  file.set_field("SomeCustomField", "a value with spaces = and an equals sign");
  std::mt19937 rng(7);
  for (int k = 0; k < frames; ++k) {
    GreyImage image(37, 23);
    for (auto& p : image.pixels) p = static_cast<std::uint8_t>(rng());
    FieldList fields{{"Timestamp", std::to_string(0.05 * k)}, {"UnknownThing", "x y z"}};
    file.add_frame(std::move(image), std::move(fields));
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m(0, 3) = 0.1 * k + 1.0 / 3.0;
    m(1, 2) = -1e-17;
    file.set_transform("ProbeToTracker", k, m,
                       k == 2 ? TrackingStatus::kInvalid : TrackingStatus::kValid);
  }
  return file;
}

TEST(SequenceFile, WrittenFileReloadsWithEveryFieldAndExactNumbers) {
  const SequenceFile file = synthetic(5);
  for (const bool compress : {true, false}) {
    const auto path = temp_path(compress ? "synthetic.igs.mha" : "synthetic.seq.mha");
    ASSERT_TRUE(write_sequence_file(file, path, {compress, 1}));
    const auto reread = read_sequence_file(path);
    ASSERT_TRUE(reread) << reread.message();
    expect_same(file, *reread);
    EXPECT_EQ(reread->field("SomeCustomField"), "a value with spaces = and an equals sign");
    EXPECT_EQ(reread->transform_status("ProbeToTracker", 2), TrackingStatus::kInvalid);
    EXPECT_EQ(reread->transform_status("ProbeToTracker", 3), TrackingStatus::kValid);
    // Shortest round-trip formatting: doubles come back bit for bit.
    EXPECT_EQ((*reread->transform("ProbeToTracker", 4))(0, 3), 0.4 + 1.0 / 3.0);
    EXPECT_EQ((*reread->transform("ProbeToTracker", 4))(1, 2), -1e-17);
  }
}

TEST(SequenceFile, AddFrameRejectsSizeChanges) {
  SequenceFile file;
  file.add_frame(GreyImage(4, 3));
  EXPECT_THROW(file.add_frame(GreyImage(3, 4)), std::invalid_argument);
  EXPECT_THROW(file.add_frame(GreyImage()), std::invalid_argument);
}

// Writes `header` followed by `payload` and returns the reader's message.
std::string read_error(const std::string& name, const std::string& header,
                       const std::string& payload = "") {
  const auto path = temp_path(name);
  {
    std::ofstream out(path, std::ios::binary);
    out << header << payload;
  }
  const auto result = read_sequence_file(path);
  EXPECT_FALSE(result) << name << " was accepted";
  return result ? std::string() : result.message();
}

TEST(SequenceFile, MalformedHeadersGiveClearErrors) {
  const std::string base = "ObjectType = Image\nNDims = 3\n";
  auto contains = [](const std::string& message, const std::string& part) {
    EXPECT_NE(message.find(part), std::string::npos) << message;
  };
  contains(read_error("nofile.mha", base + "DimSize = 2 2 1\nElementType = MET_UCHAR\n", "xxxx"),
           "ElementDataFile");
  contains(read_error("nodim.mha", base + "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n"),
           "DimSize");
  contains(read_error("baddim.mha",
                      base + "DimSize = 2 x 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n"),
           "DimSize = '2 x 1'");
  contains(read_error("float.mha",
                      base + "DimSize = 2 2 1\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n"),
           "MET_FLOAT");
  contains(read_error("ndims.mha",
                      "NDims = 4\nDimSize = 2 2 1 1\nElementType = MET_UCHAR\n"
                      "ElementDataFile = LOCAL\n"),
           "NDims");
  contains(read_error("notkv.mha", base + "this is not a field\nElementDataFile = LOCAL\n"),
           "header line 3");
  contains(read_error("short.mha",
                      base + "DimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
                      "12345"),
           "frame 1 is incomplete");
  contains(read_error("frames.mha",
                      base + "DimSize = 2 2 1\nElementType = MET_UCHAR\n"
                             "Seq_Frame0003_Timestamp = 1\nElementDataFile = LOCAL\n",
                      "1234"),
           "frame 3");
  contains(read_error("corrupt.mha",
                      base + "DimSize = 2 2 1\nElementType = MET_UCHAR\nCompressedData = True\n"
                             "ElementDataFile = LOCAL\n",
                      "not zlib at all"),
           "corrupt");
  // A .mhd's pixel file is read beside it (pose_chain_test.cpp); a missing one is named.
  contains(read_error("external.mha", base + "DimSize = 2 2 1\nElementType = MET_UCHAR\n"
                                             "ElementDataFile = frames_absent.raw\n"),
           "ElementDataFile = frames_absent.raw: cannot open");
  const auto missing = read_sequence_file(temp_path("does_not_exist.mha"));
  ASSERT_FALSE(missing);
  contains(missing.message(), "cannot read sequence file " +
                                  temp_path("does_not_exist.mha").string() + ": no such file");
}

// What `segment` checks before using a sweep (issue 27): orientation, timestamps, rigid poses.
TEST(CheckTrackedSweep, OrientationTimestampsAndRigidPoses) {
  auto sweep = [] {
    SequenceFile file;
    for (int k = 0; k < 3; ++k) {
      file.add_frame(GreyImage(4, 4));
      Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
      pose(2, 3) = k;
      file.set_transform("ProbeToTracker", static_cast<std::size_t>(k), pose,
                         TrackingStatus::kValid);
      file.set_frame_field(static_cast<std::size_t>(k), "Timestamp", std::to_string(0.1 * k));
    }
    return file;
  };
  EXPECT_TRUE(check_tracked_sweep(sweep(), "s.igs.mha"));
  for (const char* code : {"MF", "MFA"}) {
    SequenceFile file = sweep();
    file.set_field("UltrasoundImageOrientation", code);
    EXPECT_TRUE(check_tracked_sweep(file, "s.igs.mha")) << code;
  }
  auto message = [](const SequenceFile& file) {
    const Status status = check_tracked_sweep(file, "s.igs.mha");
    EXPECT_FALSE(status);
    return status ? std::string() : status.message();
  };
  SequenceFile file = sweep();
  file.set_field("UltrasoundImageOrientation", "UN");
  EXPECT_NE(message(file).find("UltrasoundImageOrientation = UN is not supported"),
            std::string::npos);
  file.set_field("UltrasoundImageOrientation", "XYZ");
  EXPECT_NE(message(file).find("'XYZ' is not a PLUS orientation"), std::string::npos);
  file = sweep();
  file.set_frame_field(1, "Timestamp", "inf");
  EXPECT_NE(message(file).find("frame 1: Timestamp = 'inf'"), std::string::npos);
  file = sweep();
  Eigen::Matrix4d sheared = Eigen::Matrix4d::Identity();
  sheared(0, 1) = 0.01;  // 1e-2 off orthonormal: beyond the 1e-3 that file rounding explains
  file.set_transform("ProbeToTracker", 2, sheared, TrackingStatus::kValid);
  EXPECT_NE(message(file).find("frame 2: ProbeToTrackerTransform"), std::string::npos);
  // The same pose marked INVALID is not used, so not checked.
  file.set_transform("ProbeToTracker", 2, sheared, TrackingStatus::kInvalid);
  EXPECT_TRUE(check_tracked_sweep(file, "s.igs.mha"));
}

}  // namespace
}  // namespace sonoshape::acquisition::sequence_file_test
