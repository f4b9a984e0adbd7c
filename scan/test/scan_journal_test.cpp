// The keyframe journal (docs/formats/scan-journal.md): records read back exactly, a torn tail
// is dropped at any cut, a full disk (ENOSPC injected through JournalIo) keeps the file a prefix
// of the keyframes and the held ones are written once it has room, and atomic file writes.
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "sonoshape/scan/journal.hpp"
#include "sonoshape/testing/temp_dir.hpp"

namespace sonoshape::scan::scan_journal_test {
namespace {

namespace fs = std::filesystem;

JournalKeyframe keyframe(int k) {
  JournalKeyframe out;
  out.frame_index = 10 * k + 3;
  // Numbers without a short decimal form: the journal must give back the same doubles.
  out.slice.origin_mm = Vec3(0.1 * k, -1.0 / 3.0, 2.0 + k / 7.0);
  out.slice.timestamp_s = k / 30.0;
  out.slice.regions.push_back({1, {{0, 0}, {10.0 / 3.0, 0}, {1, 5.0 + k / 9.0}}, {}});
  for (int i = 0; i < 4; ++i) out.plane.corners_mm[i] = Vec3(i / 3.0, k, -i * 0.7);
  out.plane.normal = Vec3(0, 0, 1);
  return out;
}

std::string bytes_of(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

void expect_same(const JournalKeyframe& a, const JournalKeyframe& b) {
  EXPECT_EQ(a.frame_index, b.frame_index);
  EXPECT_EQ(a.slice.origin_mm, b.slice.origin_mm);
  EXPECT_EQ(a.slice.timestamp_s, b.slice.timestamp_s);
  ASSERT_EQ(a.slice.regions.size(), b.slice.regions.size());
  EXPECT_EQ(a.slice.regions[0].outer, b.slice.regions[0].outer);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(a.plane.corners_mm[i], b.plane.corners_mm[i]);
}

TEST(ScanJournal, KeyframesReadBackExactlyWithTheScansArguments) {
  testing::TempDir dir;
  const fs::path path = dir.path() / kJournalName;
  auto journal = KeyframeJournal::create(path, {"--source", "sim:default"});
  ASSERT_TRUE(journal) << journal.message();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*journal)->append(keyframe(k)));
  ASSERT_TRUE((*journal)->finish(3));
  const auto read = read_journal(path);
  ASSERT_TRUE(read) << read.message();
  EXPECT_EQ(read->arguments, (std::vector<std::string>{"--source", "sim:default"}));
  ASSERT_EQ(read->keyframes.size(), 3u);
  for (int k = 0; k < 3; ++k) expect_same(read->keyframes[k], keyframe(k));
  EXPECT_TRUE(read->finished);
  EXPECT_FALSE(read->torn_tail);
  EXPECT_EQ(read->valid_bytes, fs::file_size(path));
}

TEST(ScanJournal, EveryCutOfTheLastRecordIsATornTailThatResumesCleanly) {
  testing::TempDir dir;
  const fs::path path = dir.path() / kJournalName;
  auto journal = KeyframeJournal::create(path, {"--source", "sim:default"});
  ASSERT_TRUE(journal);
  ASSERT_TRUE((*journal)->append(keyframe(0)));
  const std::uintmax_t one = fs::file_size(path);
  ASSERT_TRUE((*journal)->append(keyframe(1)));
  journal->reset();
  const std::string whole = bytes_of(path);
  const fs::path cut = dir.path() / "cut.journal";
  for (std::size_t size = one + 1; size < whole.size(); size += 7) {
    std::ofstream(cut, std::ios::binary | std::ios::trunc) << whole.substr(0, size);
    const auto read = read_journal(cut);
    ASSERT_TRUE(read) << size << ": " << read.message();
    EXPECT_EQ(read->keyframes.size(), 1u) << size;
    ASSERT_TRUE(read->torn_tail) << size;
    EXPECT_EQ(read->valid_bytes, one);
  }
  // Resuming cuts the tail and appends after the whole records.
  std::ofstream(cut, std::ios::binary | std::ios::trunc) << whole.substr(0, one + 20);
  const auto torn = read_journal(cut);
  ASSERT_TRUE(torn);
  auto reopened = KeyframeJournal::reopen(cut, *torn, keyframe(0).frame_index);
  ASSERT_TRUE(reopened) << reopened.message();
  ASSERT_TRUE((*reopened)->append(keyframe(5)));
  const auto resumed = read_journal(cut);
  ASSERT_TRUE(resumed) << resumed.message();
  EXPECT_FALSE(resumed->torn_tail);
  EXPECT_EQ(resumed->resumes, 1u);
  ASSERT_EQ(resumed->keyframes.size(), 2u);
  expect_same(resumed->keyframes[1], keyframe(5));
}

TEST(ScanJournal, AFullDiskKeepsAPrefixAndTheHeldKeyframesAreWrittenWhenThereIsRoom) {
  testing::TempDir dir;
  const fs::path path = dir.path() / kJournalName;
  // A disk that fills after the first keyframe, until room is made.
  std::uint64_t room = 0;
  bool full = true;
  JournalIo io;
  io.write_at = [&](int fd, const char* data, std::size_t size, std::uint64_t offset) -> int {
    if (full && offset + size > room) {
      // Like the kernel: what fits is written, then ENOSPC.
      const std::size_t fits = offset < room ? static_cast<std::size_t>(room - offset) : 0;
      if (fits > 0 && ::pwrite(fd, data, fits, static_cast<off_t>(offset)) < 0) return errno;
      return ENOSPC;
    }
    return ::pwrite(fd, data, size, static_cast<off_t>(offset)) == static_cast<ssize_t>(size) ? 0
                                                                                              : EIO;
  };
  auto journal = KeyframeJournal::create(path, {"--source", "sim:default"}, io);
  ASSERT_TRUE(journal);
  full = false;
  ASSERT_TRUE((*journal)->append(keyframe(0)));
  full = true;
  room = fs::file_size(path) + 100;  // not a whole record more
  const Status failed = (*journal)->append(keyframe(1));
  ASSERT_FALSE(failed);
  EXPECT_NE(failed.message().find("No space left on device"), std::string::npos)
      << failed.message();
  EXPECT_NE(failed.message().find(kJournalName), std::string::npos) << failed.message();
  EXPECT_FALSE((*journal)->append(keyframe(2)));
  EXPECT_EQ((*journal)->pending(), 2u);
  EXPECT_EQ((*journal)->written(), 1u);
  // The file was cut back to its whole records: no torn tail, one keyframe.
  auto read = read_journal(path);
  ASSERT_TRUE(read) << read.message();
  EXPECT_FALSE(read->torn_tail);
  EXPECT_EQ(read->keyframes.size(), 1u);
  full = false;
  ASSERT_TRUE((*journal)->append(keyframe(3)));
  EXPECT_EQ((*journal)->pending(), 0u);
  read = read_journal(path);
  ASSERT_TRUE(read) << read.message();
  ASSERT_EQ(read->keyframes.size(), 4u);
  for (int k = 0; k < 4; ++k) expect_same(read->keyframes[k], keyframe(k));
}

TEST(ScanJournal, ABadHeaderOrANewerVersionIsRefusedWithTheFix) {
  testing::TempDir dir;
  const fs::path path = dir.path() / kJournalName;
  std::ofstream(path, std::ios::binary) << "not a journal at all";
  auto read = read_journal(path);
  ASSERT_FALSE(read);
  EXPECT_NE(read.message().find("not a sonoshape scan journal"), std::string::npos);
  std::string header("SNSHJRNL\x02\0\0\0\0\0\0\0", 16);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << header;
  read = read_journal(path);
  ASSERT_FALSE(read);
  EXPECT_NE(read.message().find("journal version 2; this sonoshape reads version 1"),
            std::string::npos)
      << read.message();
}

TEST(ScanJournal, WriteFileAtomicallyReplacesWholeAndLeavesNoTemporaryFile) {
  testing::TempDir dir;
  const fs::path path = dir.path() / "scan.json";
  ASSERT_TRUE(write_file_atomically(path, "{\"a\": 1}\n"));
  ASSERT_TRUE(write_file_atomically(path, "{\"a\": 2}\n"));
  EXPECT_EQ(bytes_of(path), "{\"a\": 2}\n");
  EXPECT_FALSE(fs::exists(dir.path() / ".partial-scan.json"));
  const Status missing = write_file_atomically(dir.path() / "no" / "such" / "scan.json", "x");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.message().find("cannot create"), std::string::npos) << missing.message();
}

}  // namespace
}  // namespace sonoshape::scan::scan_journal_test

namespace sonoshape::scan::scan_journal_test {
namespace {

std::uint32_t u32_at(const std::string& bytes, std::size_t at) {
  std::uint32_t value = 0;
  for (int k = 3; k >= 0; --k) value = (value << 8) | static_cast<unsigned char>(bytes[at + k]);
  return value;
}

// The whole records of a journal (length, CRC and payload each), after its 16-byte header.
std::vector<std::string> records_of(const std::string& bytes) {
  std::vector<std::string> records;
  for (std::size_t at = 16; at + 8 <= bytes.size();) {
    const std::size_t size = 8 + u32_at(bytes, at);
    records.push_back(bytes.substr(at, size));
    at += size;
  }
  return records;
}

// A well-formed record (right length and CRC) around `payload`.
std::string record_of(const std::string& payload) {
  std::string out;
  const auto put = [&](std::uint32_t value) {
    for (int k = 0; k < 4; ++k) out.push_back(static_cast<char>((value >> (8 * k)) & 0xff));
  };
  put(static_cast<std::uint32_t>(payload.size()));
  put(static_cast<std::uint32_t>(
      crc32(0, reinterpret_cast<const Bytef*>(payload.data()), static_cast<uInt>(payload.size()))));
  return out + payload;
}

// Issue 40: a journal with a repeated keyframe record resumed to 51 slices instead of 50, a
// keyframe after an `end` record was taken, and a record `[1]` failed with
// "[json.exception.type_error.306] ...". Each record has its CRC right: only its content lies.
TEST(ScanJournal, RepeatedKeyframesKeyframesAfterTheEndAndNonObjectRecordsAreRefused) {
  testing::TempDir dir;
  const fs::path path = dir.path() / kJournalName;
  auto journal = KeyframeJournal::create(path, {"--source", "sim:default"});
  ASSERT_TRUE(journal) << journal.message();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*journal)->append(keyframe(k)));
  ASSERT_TRUE((*journal)->finish(3));
  journal->reset();
  const std::string bytes = bytes_of(path);
  const std::string header = bytes.substr(0, 16);
  const std::vector<std::string> r = records_of(bytes);  // scan, 3 keyframes, end
  ASSERT_EQ(r.size(), 5u);
  const auto read_of = [&](const std::vector<std::string>& records) {
    std::string crafted = header;
    for (const std::string& record : records) crafted += record;
    std::ofstream(path, std::ios::binary | std::ios::trunc) << crafted;
    return read_journal(path);
  };
  const auto whole = read_of(r);
  ASSERT_TRUE(whole) << whole.message();
  EXPECT_EQ(whole->keyframes.size(), 3u);

  const auto repeated = read_of({r[0], r[1], r[2], r[2], r[3], r[4]});
  ASSERT_FALSE(repeated);
  EXPECT_NE(repeated.message().find("record 3 at byte"), std::string::npos) << repeated.message();
  EXPECT_NE(repeated.message().find("keyframe \"n\" is 1 but 2 keyframes come before it"),
            std::string::npos)
      << repeated.message();

  const auto after_end = read_of({r[0], r[1], r[2], r[4], r[3]});
  ASSERT_FALSE(after_end);
  EXPECT_NE(after_end.message().find("a keyframe after the scan's end record"), std::string::npos)
      << after_end.message();
  // After a resume record, keyframes go on.
  const auto resumed = read_of({r[0], r[1], r[2], r[4], record_of(R"({"type":"resume"})"), r[3]});
  ASSERT_TRUE(resumed) << resumed.message();
  EXPECT_EQ(resumed->keyframes.size(), 3u);

  const auto array = read_of({r[0], record_of("[1]")});
  ASSERT_FALSE(array);
  EXPECT_NE(array.message().find("record 1 at byte"), std::string::npos) << array.message();
  EXPECT_NE(array.message().find("not a journal record"), std::string::npos) << array.message();
  EXPECT_EQ(array.message().find("json.exception"), std::string::npos) << array.message();
}

}  // namespace
}  // namespace sonoshape::scan::scan_journal_test
