// NRRD sequences: PLUS's .igs.nrrd (against the .mha copy of the same recording) and 3D Slicer
// .seq.nrrd image sequences, the latter written here in Slicer's layout (Slicer's developer
// guide, "Volume sequence file format (.seq.nrrd)"): 4D, `kinds: domain domain domain list`,
// `axis 3 index type/values`, `DataNodeClassName`, gzip, plus the older list-first layout.
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>
#include <string>

#include "sonoshape/acquisition/sequence_file.hpp"

namespace sonoshape::acquisition::nrrd_sequence_test {
namespace {

const std::filesystem::path kPlusDir = std::filesystem::path(SONOSHAPE_DATA_DIR) / "plus";

std::filesystem::path temp_path(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("sonoshape_nrrd_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  return dir / name;
}

std::uint64_t pixel_sum(const GreyImage& image) {
  return std::accumulate(image.pixels.begin(), image.pixels.end(), std::uint64_t{0});
}

void expect_contains(const std::string& message, const std::string& part) {
  EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
}

TEST(NrrdSequence, PlusNrrdAndMhaCopiesOfOneRecordingReadToTheSameFrames) {
  const auto nrrd = read_sequence_file(kPlusDir / "NwirePhantomFreehand.igs.nrrd");
  ASSERT_TRUE(nrrd) << nrrd.message();
  const auto mha = read_sequence_file(kPlusDir / "NwirePhantomFreehand.igs.mha");
  ASSERT_TRUE(mha) << mha.message();

  ASSERT_EQ(nrrd->width(), 820);
  ASSERT_EQ(nrrd->height(), 616);
  ASSERT_EQ(nrrd->frame_count(), 97u);
  ASSERT_EQ(mha->width(), nrrd->width());
  ASSERT_EQ(mha->height(), nrrd->height());
  ASSERT_EQ(mha->frame_count(), nrrd->frame_count());
  EXPECT_EQ(nrrd->field("UltrasoundImageOrientation"), "MFA");
  EXPECT_EQ(nrrd->field("UltrasoundImageType"), "BRIGHTNESS");
  EXPECT_EQ(nrrd->field("UltrasoundImageOrientation"), mha->field("UltrasoundImageOrientation"));
  // PLUS's 2D pixel space is no placement in 3D.
  EXPECT_FALSE(nrrd->field("ImageToReferenceTransform"));
  EXPECT_EQ(nrrd->field("space directions"), "(1,0) (0,1) none");
  EXPECT_FALSE(nrrd->field("encoding"));  // layout fields are consumed

  // Numbers from the header text and an independent gzip decode (Python's gzip module).
  EXPECT_DOUBLE_EQ(*nrrd->timestamp_s(0), 345.627957);
  EXPECT_DOUBLE_EQ(*nrrd->timestamp_s(96), 355.783014);
  EXPECT_DOUBLE_EQ((*nrrd->transform("ProbeToTracker", 96))(0, 3), -188.788);
  EXPECT_EQ(nrrd->frame_field(0, "ImageStatus"), "OK");  // PLUS NRRD's "Status"
  EXPECT_EQ(nrrd->transform_status("StylusToTracker", 0), TrackingStatus::kInvalid);
  EXPECT_EQ(pixel_sum(nrrd->image(0)), 180054u);
  EXPECT_EQ(pixel_sum(nrrd->image(96)), 1311665u);
  EXPECT_EQ(nrrd->image(96).at(529, 206), 107);
  EXPECT_EQ(nrrd->image(0).at(615, 287), 81);

  const auto names = nrrd->transform_names();
  EXPECT_EQ(names, mha->transform_names());
  for (std::size_t k = 0; k < nrrd->frame_count(); ++k) {
    ASSERT_EQ(nrrd->image(k), mha->image(k)) << "pixels of frame " << k;
    // Every per-frame field, text for text (transforms, statuses, timestamps).
    ASSERT_EQ(nrrd->frame_fields(k), mha->frame_fields(k)) << "fields of frame " << k;
    ASSERT_EQ(nrrd->timestamp_s(k), mha->timestamp_s(k));
    for (const std::string& name : names) {
      ASSERT_EQ(*nrrd->transform(name, k), *mha->transform(name, k)) << name << " " << k;
      ASSERT_EQ(nrrd->transform_status(name, k), mha->transform_status(name, k));
    }
  }
  EXPECT_TRUE(require_tracking(*nrrd, "NwirePhantomFreehand.igs.nrrd"));
}

TEST(NrrdSequence, ReadNrrdWritesBackAsMetaImage) {
  const auto nrrd = read_sequence_file(kPlusDir / "NwirePhantomFreehand.igs.nrrd");
  ASSERT_TRUE(nrrd) << nrrd.message();
  const auto path = temp_path("from_nrrd.igs.mha");
  ASSERT_TRUE(write_sequence_file(*nrrd, path, {true, 1}));
  const auto reread = read_sequence_file(path);
  ASSERT_TRUE(reread) << reread.message();
  ASSERT_EQ(reread->frame_count(), nrrd->frame_count());
  for (std::size_t k = 0; k < nrrd->frame_count(); k += 12) {
    EXPECT_EQ(reread->image(k), nrrd->image(k));
    EXPECT_EQ(reread->frame_fields(k), nrrd->frame_fields(k));
  }
  EXPECT_EQ(reread->field("UltrasoundImageOrientation"), "MFA");
}

// --- Synthetic Slicer sequences -------------------------------------------------------------

std::string gzip(const std::string& bytes) {
  z_stream stream{};
  // windowBits 15 + 16: a gzip member, as teem writes for `encoding: gzip`.
  EXPECT_EQ(deflateInit2(&stream, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&stream, bytes.size()) + 32, '\0');
  stream.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
  stream.avail_in = static_cast<uInt>(bytes.size());
  stream.next_out = reinterpret_cast<Bytef*>(out.data());
  stream.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&stream, Z_FINISH), Z_STREAM_END);
  out.resize(stream.total_out);
  deflateEnd(&stream);
  return out;
}

void write_file(const std::filesystem::path& path, const std::string& header,
                const std::string& payload = "") {
  std::ofstream out(path, std::ios::binary);
  out << header << payload;
}

struct SyntheticFrames {
  int w = 7, h = 5, n = 4;
  std::vector<GreyImage> images;
  std::vector<double> times_s = {12.5, 12.55, 12.625, 13.0};
};

SyntheticFrames make_frames() {
  SyntheticFrames f;
  std::mt19937 rng(11);
  for (int k = 0; k < f.n; ++k) {
    GreyImage image(f.w, f.h);
    for (auto& p : image.pixels) p = static_cast<std::uint8_t>(rng());
    f.images.push_back(image);
  }
  return f;
}

// Frames as Slicer stores them with the list axis last: x fastest, then y, then frames.
std::string frames_last(const SyntheticFrames& f) {
  std::string bytes;
  for (const GreyImage& image : f.images)
    bytes.append(reinterpret_cast<const char*>(image.pixels.data()), image.pixels.size());
  return bytes;
}

// The list axis first (older Slicer): the frame index varies fastest.
std::string frames_first(const SyntheticFrames& f) {
  std::string bytes;
  for (int j = 0; j < f.h; ++j)
    for (int i = 0; i < f.w; ++i)
      for (const GreyImage& image : f.images) bytes += static_cast<char>(image.at(i, j));
  return bytes;
}

// A Slicer-style header; `layout` holds sizes, directions and kinds in the chosen axis order.
std::string slicer_header(const std::string& layout, const std::string& extra = "") {
  return "NRRD0004\n"
         "# Complete NRRD file format specification at:\n"
         "# http://teem.sourceforge.net/nrrd/format.html\n"
         "type: unsigned char\n"
         "dimension: 4\n"
         "space: left-posterior-superior\n" +
         layout +
         "endian: little\n"
         "space origin: (-10.5,20,30.25)\n"
         "DataNodeClassName:=vtkMRMLScalarVolumeNode\n"
         "ultrasound image orientation:=MF\n" +
         extra;
}

const std::string kListLast =
    "sizes: 7 5 1 4\n"
    "space directions: (0.2,0,0) (0,0,-0.25) (0,0.5,0) none\n"
    "kinds: domain domain domain list\n"
    "labels: \"\" \"\" \"\" \"frame\"\n";

const std::string kTimes =
    "axis 3 index type:=numeric\naxis 3 index values:=12.5 12.55 12.625 13\n";

void expect_frames(const SequenceFile& file, const SyntheticFrames& f) {
  ASSERT_EQ(file.width(), f.w);
  ASSERT_EQ(file.height(), f.h);
  ASSERT_EQ(file.frame_count(), static_cast<std::size_t>(f.n));
  for (int k = 0; k < f.n; ++k) {
    EXPECT_EQ(file.image(static_cast<std::size_t>(k)), f.images[static_cast<std::size_t>(k)])
        << "frame " << k;
    EXPECT_EQ(file.timestamp_s(static_cast<std::size_t>(k)),
              f.times_s[static_cast<std::size_t>(k)]);
  }
}

TEST(NrrdSequence, SlicerImageSequenceGivesFramesTimesAndImageGeometry) {
  const SyntheticFrames f = make_frames();
  const auto path = temp_path("us.seq.nrrd");
  write_file(path,
             slicer_header(kListLast + "encoding: gzip\n",
                           kTimes + "axis 3 item 2 AcquisitionTime:=2024-06-21T10:32:45.120Z\n") +
                 "\n",
             gzip(frames_last(f)));
  const auto file = read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  expect_frames(*file, f);
  EXPECT_EQ(file->field("UltrasoundImageOrientation"), "MF");
  EXPECT_EQ(file->field("DataNodeClassName"), "vtkMRMLScalarVolumeNode");
  EXPECT_EQ(file->field("space"), "left-posterior-superior");
  EXPECT_EQ(file->frame_field(2, "AcquisitionTime"), "2024-06-21T10:32:45.120Z");
  EXPECT_FALSE(file->frame_field(1, "AcquisitionTime"));

  // Pixel (i, j) lies at origin + i * dir0 + j * dir1 in the file's (LPS) space.
  const auto text = file->field("ImageToReferenceTransform");
  ASSERT_TRUE(text);
  const auto m = parse_matrix(*text);
  ASSERT_TRUE(m);
  const Eigen::Vector4d p = *m * Eigen::Vector4d(3, 2, 0, 1);
  EXPECT_DOUBLE_EQ(p.x(), -10.5 + 3 * 0.2);
  EXPECT_DOUBLE_EQ(p.y(), 20.0);
  EXPECT_DOUBLE_EQ(p.z(), 30.25 - 2 * 0.25);
  // The slice axis as given.
  EXPECT_EQ(Eigen::Vector3d(m->block<3, 1>(0, 2)), Eigen::Vector3d(0, 0.5, 0));

  // Image only: no per-frame tracking, and segment/replay say so.
  const Status tracked = require_tracking(*file, path);
  ASSERT_FALSE(tracked);
  expect_contains(tracked.message(), path.string());
  expect_contains(tracked.message(), "Slicer");
  expect_contains(tracked.message(), "ProbeToTrackerTransform");
  expect_contains(tracked.message(), ".igs.nrrd");
}

TEST(NrrdSequence, OlderSlicerListFirstLayoutReadsTheSameFrames) {
  const SyntheticFrames f = make_frames();
  const auto path = temp_path("list_first.seq.nrrd");
  write_file(path,
             slicer_header("sizes: 4 7 5 1\n"
                           "space directions: none (0.2,0,0) (0,0,-0.25) (0,0.5,0)\n"
                           "kinds: list domain domain domain\n"
                           "encoding: raw\n",
                           "axis 0 index type:=numeric\n"
                           "axis 0 index values:=12.5 12.55 12.625 13\n") +
                 "\n",
             frames_first(f));
  const auto file = read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  expect_frames(*file, f);
  EXPECT_TRUE(file->field("ImageToReferenceTransform"));
}

TEST(NrrdSequence, TextIndexValuesAreKeptAndGiveNoTimestamps) {
  SyntheticFrames f = make_frames();
  const auto path = temp_path("text_index.seq.nrrd");
  write_file(path,
             slicer_header(kListLast + "encoding: raw\n",
                           "axis 3 index type:=text\naxis 3 index values:=pre post%20op b c\n") +
                 "\n",
             frames_last(f));
  const auto file = read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  EXPECT_EQ(file->frame_field(1, "SequenceIndexValue"), "post op");
  EXPECT_FALSE(file->timestamp_s(1));
}

// A detached header (.nhdr) with big-endian 16-bit samples, a line skip and a byte skip.
TEST(NrrdSequence, DetachedRawBigEndian16BitSamplesRead) {
  const SyntheticFrames f = make_frames();
  std::string samples;
  for (const char c : frames_last(f)) {
    samples += '\0';  // high byte first
    samples += c;
  }
  const auto data_path = temp_path("frames16.raw");
  write_file(data_path, "a comment line\n", "XYZ" + samples);
  const auto header_path = temp_path("frames16.nhdr");
  std::string header = slicer_header(kListLast + "encoding: raw\n", kTimes);
  header.replace(header.find("unsigned char"), 13, "ushort");
  header.replace(header.find("endian: little"), 14, "endian: big");
  header += "data file: frames16.raw\nline skip: 1\nbyte skip: 3\n";
  write_file(header_path, header);
  const auto file = read_sequence_file(header_path);
  ASSERT_TRUE(file) << file.message();
  expect_frames(*file, f);

  // byte skip -1: the samples are the last bytes of the file.
  header.replace(header.find("byte skip: 3"), 12, "byte skip: -1");
  write_file(header_path, header);
  const auto from_end = read_sequence_file(header_path);
  ASSERT_TRUE(from_end) << from_end.message();
  expect_frames(*from_end, f);
}

// Issue 40, S4: a sequence file is someone else's; its `data file` must not read this machine's
// files (they would become pixels, segmented and streamed), nor an error quote them.
TEST(NrrdSequence, DetachedDataIsReadOnlyFromTheHeadersOwnFolder) {
  namespace fs = std::filesystem;
  const SyntheticFrames f = make_frames();
  const std::string samples = frames_last(f);
  const std::string secret = "root:$6$secret-hash-of-a-password:19000:0:99999:7:::\n";
  // The header's folder, and a secret beside it (outside it).
  const fs::path base = temp_path("s4");
  const fs::path folder = base / "sequence";
  fs::create_directories(folder);
  const fs::path outside = base / "shadow";
  write_file(outside, secret + std::string(samples.size(), 'x'));
  const std::string header = slicer_header(kListLast + "encoding: raw\n", kTimes);
  const auto refused = [&](const std::string& name, const std::string& data_file) {
    const fs::path path = folder / name;
    write_file(path, header + "data file: " + data_file + "\n");
    const auto result = read_sequence_file(path);
    EXPECT_FALSE(result) << data_file << " was read";
    if (result) return std::string();
    expect_contains(result.message(), path.string());
    expect_contains(result.message(), "'data file'");
    EXPECT_EQ(result.message().find("secret-hash"), std::string::npos) << result.message();
    return result.message();
  };
  expect_contains(refused("absolute.nhdr", outside.string()), "is an absolute path");
  expect_contains(refused("up.nhdr", "../shadow"), "leads out of the header's folder ('..')");
  expect_contains(refused("up-inside.nhdr", "sub/../../shadow"), "('..')");
  fs::create_symlink(outside, folder / "frames.raw");
  expect_contains(refused("link.nhdr", "frames.raw"), "is a link that leads out of the header's");
  fs::create_directory_symlink(base, folder / "up");
  expect_contains(refused("dir-link.nhdr", "up/shadow"), "is a link that leads out");

  // A file in the folder, or below it, reads; so does a link that stays inside.
  fs::create_directories(folder / "data");
  write_file(folder / "data" / "frames.raw", samples);
  fs::create_symlink("data/frames.raw", folder / "inside-link.raw");
  for (const std::string name : {"data/frames.raw", "./data/frames.raw", "inside-link.raw"}) {
    const fs::path path = folder / "good.nhdr";
    write_file(path, header + "data file: " + name + "\n");
    const auto file = read_sequence_file(path);
    ASSERT_TRUE(file) << name << ": " << file.message();
    expect_frames(*file, f);
  }
}

TEST(NrrdSequence, ATextDecodingErrorQuotesNoDetachedFilesContent) {
  namespace fs = std::filesystem;
  const fs::path folder = temp_path("s4-text");
  fs::create_directories(folder);
  write_file(folder / "frames.txt", "root:$6$secret-hash:19000\n");
  const fs::path path = folder / "text.nhdr";
  write_file(path,
             slicer_header(kListLast + "encoding: ascii\n", kTimes) + "data file: frames.txt\n");
  const auto result = read_sequence_file(path);
  ASSERT_FALSE(result);
  expect_contains(result.message(), "text sample 0 is not an integer sample");
  EXPECT_EQ(result.message().find("secret"), std::string::npos) << result.message();
  EXPECT_EQ(result.message().find("root"), std::string::npos) << result.message();
}

TEST(NrrdSequence, TextEncodingReads) {
  const SyntheticFrames f = make_frames();
  std::string text;
  for (const char c : frames_last(f))
    text += std::to_string(static_cast<unsigned char>(c)) + (text.size() % 7 ? " " : "\n");
  const auto path = temp_path("text.seq.nrrd");
  write_file(path, slicer_header(kListLast + "encoding: text\n", kTimes) + "\n", text);
  const auto file = read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  expect_frames(*file, f);

  // Text has no byte order: 16-bit text samples read the same with `endian: big`.
  std::string header = slicer_header(kListLast + "encoding: text\n", kTimes) + "\n";
  header.replace(header.find("unsigned char"), 13, "ushort");
  header.replace(header.find("endian: little"), 14, "endian: big");
  write_file(path, header, text);
  const auto wide = read_sequence_file(path);
  ASSERT_TRUE(wide) << wide.message();
  expect_frames(*wide, f);
}

// gzip allows several members one after another (`cat a.gz b.gz`); they are one stream.
TEST(NrrdSequence, ConcatenatedGzipMembersRead) {
  const SyntheticFrames f = make_frames();
  const std::string raw = frames_last(f);
  const auto path = temp_path("members.seq.nrrd");
  write_file(path, slicer_header(kListLast + "encoding: gzip\n", kTimes) + "\n",
             gzip(raw.substr(0, 33)) + gzip(raw.substr(33)));
  const auto file = read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  expect_frames(*file, f);
}

TEST(NrrdSequence, TheContentNotTheNamePicksTheFormat) {
  const SyntheticFrames f = make_frames();
  const auto path = temp_path("really_nrrd.mha");
  write_file(path, slicer_header(kListLast + "encoding: gzip\n", kTimes) + "\n",
             gzip(frames_last(f)));
  const auto file = read_sequence_file(path);
  ASSERT_TRUE(file) << file.message();
  expect_frames(*file, f);
}

std::string nrrd_error(const std::string& name, const std::string& header,
                       const std::string& payload = "") {
  const auto path = temp_path(name);
  write_file(path, header, payload);
  const auto result = read_sequence_file(path);
  EXPECT_FALSE(result) << name << " was accepted";
  if (result) return "";
  EXPECT_NE(result.message().find(path.string()), std::string::npos) << result.message();
  return result.message();
}

TEST(NrrdSequence, UnsupportedOrMalformedFilesGiveClearErrors) {
  const SyntheticFrames f = make_frames();
  const std::string raw = frames_last(f);
  auto with = [&](const std::string& layout, const std::string& extra = kTimes) {
    return slicer_header(layout, extra) + "\n";
  };
  // 16-bit values outside 0..255 are not silently scaled.
  {
    std::string header = with(kListLast + "encoding: raw\n");
    header.replace(header.find("unsigned char"), 13, "short");
    std::string samples(raw.size() * 2, '\0');
    samples[2 * 9] = 0x2c;  // little-endian 300 at sample 9
    samples[2 * 9 + 1] = 0x01;
    expect_contains(nrrd_error("wide.seq.nrrd", header, samples), "sample 9 is 300");
  }
  expect_contains(nrrd_error("bzip.seq.nrrd", with(kListLast + "encoding: bzip2\n"), raw),
                  "'bzip2' is not supported");
  {
    std::string header = with(kListLast + "encoding: raw\n");
    header.replace(header.find("unsigned char"), 13, "float");
    expect_contains(nrrd_error("float.seq.nrrd", header, raw + raw + raw + raw), "'float'");
  }
  expect_contains(nrrd_error("volume.seq.nrrd",
                             with("sizes: 7 5 2 2\n"
                                  "space directions: (1,0,0) (0,1,0) (0,0,1) none\n"
                                  "kinds: domain domain domain list\nencoding: raw\n",
                                  "axis 3 index values:=1 2\n"),
                             raw),
                  "3D volume");
  expect_contains(nrrd_error("rgb.seq.nrrd",
                             with("sizes: 3 7 5 4\nkinds: RGB-color domain domain list\n"
                                  "encoding: raw\n"),
                             raw + raw + raw),
                  "RGB-color");
  expect_contains(
      nrrd_error("count.seq.nrrd",
                 with(kListLast + "encoding: raw\n", "axis 3 index values:=1 2 3\n"), raw),
      "lists 3 values for 4 frames");
  expect_contains(
      nrrd_error("short.seq.nrrd", with(kListLast + "encoding: raw\n"), raw.substr(0, 50)),
      "has 50 bytes");
  expect_contains(nrrd_error("truncated.seq.nrrd", with(kListLast + "encoding: gzip\n"),
                             gzip(raw).substr(0, 30)),
                  "decompresses to");
  expect_contains(
      nrrd_error("corrupt.seq.nrrd", with(kListLast + "encoding: gzip\n"), "this is not gzip data"),
      "corrupt");
  expect_contains(nrrd_error("nofile.nhdr", slicer_header(kListLast + "encoding: raw\n") +
                                                "data file: missing.raw\n"),
                  "cannot open");
  expect_contains(nrrd_error("many.nhdr", slicer_header(kListLast + "encoding: raw\n") +
                                              "data file: part%03d.raw 0 3 1\n"),
                  "several files");
  // A device would be read without end (found by fuzzing: tests/data/fuzz/sequence_nrrd/).
  expect_contains(nrrd_error("device.nhdr", slicer_header(kListLast + "encoding: raw\n") +
                                                "data file: /dev/zero\n"),
                  "'/dev/zero' is an absolute path");
  expect_contains(
      nrrd_error("frames.seq.nrrd",
                 with(kListLast + "encoding: raw\n", "Seq_Frame0009_Timestamp:=1\n"), raw),
      "frame 9");
  expect_contains(nrrd_error("nokinds.nrrd",
                             "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 7 5 4\n"
                             "encoding: raw\n\n",
                             raw),
                  "kinds");
  expect_contains(
      nrrd_error("badline.nrrd", "NRRD0004\ntype: uint8\nthis line is nothing\n\n", raw),
      "header line 3");
  expect_contains(nrrd_error("magic.nrrd", "NRRD0009\n\n", raw), "NRRD magic");
  expect_contains(nrrd_error("huge.seq.nrrd",
                             with("sizes: 2000000000 2000000000 1 4\n"
                                  "kinds: domain domain domain list\nencoding: raw\n"),
                             raw),
                  "more than 2^36 samples");
}

TEST(NrrdSequence, RequireTrackingNamesTheTransformsAFileHas) {
  SequenceFile file;
  file.add_frame(GreyImage(2, 2));
  file.set_transform("StylusToTracker", 0, Eigen::Matrix4d::Identity(), TrackingStatus::kValid);
  const Status status = require_tracking(file, "sweep.igs.mha");
  ASSERT_FALSE(status);
  expect_contains(status.message(), "sweep.igs.mha");
  expect_contains(status.message(), "StylusToTracker");
  file.set_transform("ProbeToTracker", 0, Eigen::Matrix4d::Identity(), TrackingStatus::kValid);
  EXPECT_TRUE(require_tracking(file, "sweep.igs.mha"));
}

}  // namespace
}  // namespace sonoshape::acquisition::nrrd_sequence_test

namespace sonoshape::acquisition::nrrd_sequence_test {
namespace {

// Issue 40: `sizes:` given twice was accepted (the later one taken); the format gives each field
// once, and which one the pixels follow cannot be told.
TEST(NrrdSequence, AFieldGivenTwiceIsRefusedNamingBothLines) {
  const SyntheticFrames f = make_frames();
  const auto path = temp_path("twice.seq.nrrd");
  write_file(path, slicer_header(kListLast + "sizes: 7 5 1 2\nencoding: raw\n", kTimes) + "\n",
             frames_last(f));
  const auto file = read_sequence_file(path);
  ASSERT_FALSE(file);
  expect_contains(file.message(), path.string());
  expect_contains(file.message(), "'sizes' repeats the field of header line 7");
}

}  // namespace
}  // namespace sonoshape::acquisition::nrrd_sequence_test
