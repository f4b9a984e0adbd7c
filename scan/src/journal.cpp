#include "sonoshape/scan/journal.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <utility>

#include "sonoshape/core/input_file.hpp"
#include "sonoshape/core/slice_io.hpp"

namespace sonoshape::scan {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// The file starts with these 8 bytes, then the version (u32, little-endian) and 4 zero bytes.
constexpr char kMagic[8] = {'S', 'N', 'S', 'H', 'J', 'R', 'N', 'L'};
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kHeaderBytes = 16;
// A record: payload length (u32 LE), CRC-32 of the payload (u32 LE), the payload (JSON).
constexpr std::size_t kRecordHeaderBytes = 8;
// No slice comes near this; a larger length is corruption, not a slice.
constexpr std::uint32_t kMaxRecordBytes = 64u << 20;

void put_u32(std::string& out, std::uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xFFu));
}

std::uint32_t get_u32(const std::string& in, std::size_t at) {
  std::uint32_t value = 0;
  for (int i = 0; i < 4; ++i)
    value |= static_cast<std::uint32_t>(static_cast<unsigned char>(in[at + i])) << (8 * i);
  return value;
}

std::uint32_t crc32_of(const char* data, std::size_t size) {
  return static_cast<std::uint32_t>(
      ::crc32(0L, reinterpret_cast<const Bytef*>(data), static_cast<uInt>(size)));
}

std::string encode_record(const json& payload) {
  const std::string text = payload.dump();
  std::string out;
  out.reserve(kRecordHeaderBytes + text.size());
  put_u32(out, static_cast<std::uint32_t>(text.size()));
  put_u32(out, crc32_of(text.data(), text.size()));
  return out + text;
}

std::string header_bytes() {
  std::string out(kMagic, sizeof(kMagic));
  put_u32(out, kVersion);
  put_u32(out, 0);
  return out;
}

std::string system_reason(int error) {
  std::string reason = std::strerror(error);
  if (error == ENOSPC || error == EDQUOT || error == EFBIG)
    reason += " (free space on the disk of --out, or choose another --out)";
  return reason;
}

// POSIX pwrite until everything is written; 0 or the errno.
int posix_write_at(int fd, const char* data, std::size_t size, std::uint64_t offset) {
  while (size > 0) {
    const ssize_t n = ::pwrite(fd, data, size, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (n == 0) return EIO;
    data += n;
    size -= static_cast<std::size_t>(n);
    offset += static_cast<std::uint64_t>(n);
  }
  return 0;
}

int sync_fd(int fd) {
  while (::fsync(fd) != 0)
    if (errno != EINTR) return errno;
  return 0;
}

// fsync of a directory: makes a rename or a new entry in it durable.
Status sync_directory(const fs::path& directory) {
  const fs::path dir = directory.empty() ? fs::path(".") : directory;
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return Status::error("cannot open " + dir.string() + ": " + system_reason(errno));
  const int error = sync_fd(fd);
  ::close(fd);
  if (error) return Status::error("cannot sync " + dir.string() + ": " + system_reason(error));
  return Status::ok();
}

json plane_json(const tracking::FramePlane& plane) {
  json corners = json::array();
  for (const Vec3& c : plane.corners_mm) corners.push_back({c.x(), c.y(), c.z()});
  return {{"corners_mm", corners},
          {"normal", {plane.normal.x(), plane.normal.y(), plane.normal.z()}}};
}

Vec3 vec3_of(const json& value) {
  if (!value.is_array() || value.size() != 3 || !value[0].is_number() || !value[1].is_number() ||
      !value[2].is_number())
    throw std::invalid_argument("expected [x, y, z]");
  return Vec3(value[0].get<double>(), value[1].get<double>(), value[2].get<double>());
}

tracking::FramePlane plane_of(const json& value) {
  tracking::FramePlane plane;
  const json& corners = value.at("corners_mm");
  if (!corners.is_array() || corners.size() != 4)
    throw std::invalid_argument("plane.corners_mm: expected 4 corners");
  for (std::size_t i = 0; i < 4; ++i) plane.corners_mm[i] = vec3_of(corners[i]);
  plane.normal = vec3_of(value.at("normal"));
  return plane;
}

Result<JournalKeyframe> keyframe_of(const json& record, const std::string& where) {
  JournalKeyframe keyframe;
  try {
    keyframe.frame_index = record.at("frame").get<std::int64_t>();
    keyframe.plane = plane_of(record.at("plane"));
  } catch (const std::exception& e) {
    return Status::error(where + ": " + e.what());
  }
  const auto slice_it = record.find("slice");
  if (slice_it == record.end()) return Status::error(where + ": no \"slice\"");
  auto slice = parse_slice_json(slice_it->dump(), where + ", slice");
  if (!slice) return slice.status();
  keyframe.slice = std::move(*slice);
  return keyframe;
}

bool all_zero(const std::string& bytes, std::size_t from) {
  return std::all_of(bytes.begin() + static_cast<std::ptrdiff_t>(from), bytes.end(),
                     [](char c) { return c == 0; });
}

// Applies one whole record to `contents`.
Status apply_record(const std::string& payload, const std::string& where,
                    JournalContents& contents) {
  json record;
  try {
    record = json::parse(payload);
  } catch (const std::exception& e) {
    return Status::error(where + ": not JSON (" + e.what() + ")");
  }
  if (!record.is_object() || !record.contains("type") || !record["type"].is_string())
    return Status::error(where +
                         ": not a journal record (a JSON object with a \"type\" string), "
                         "but " +
                         record.dump().substr(0, 60) + "; the journal was altered");
  const std::string type = record["type"].get<std::string>();
  if (type == "scan") {
    try {
      contents.arguments = record.at("arguments").get<std::vector<std::string>>();
    } catch (const std::exception& e) {
      return Status::error(where + ": \"arguments\": " + e.what());
    }
    if (const auto it = record.find("working_directory"); it != record.end()) {
      if (!it->is_string() || it->get<std::string>().empty() ||
          !fs::path(it->get<std::string>()).is_absolute())
        return Status::error(where + ": \"working_directory\" is not an absolute path");
      contents.working_directory = it->get<std::string>();
    }
  } else if (type == "keyframe") {
    // After `end` only a `resume` may follow; and keyframe n is the n-th: a repeated or a
    // missing record would rebuild another scan than the one that ran.
    if (contents.finished)
      return Status::error(where +
                           ": a keyframe after the scan's end record with no resume "
                           "record between them; the journal was altered");
    const auto n = record.find("n");
    if (n == record.end() || !n->is_number_unsigned() ||
        n->get<std::uint64_t>() != contents.keyframes.size())
      return Status::error(where + ": keyframe \"n\" is " +
                           (n == record.end() ? std::string("missing") : n->dump()) + " but " +
                           std::to_string(contents.keyframes.size()) +
                           " keyframes come before it (a repeated or missing record); the "
                           "journal was altered");
    auto keyframe = keyframe_of(record, where);
    if (!keyframe) return keyframe.status();
    contents.keyframes.push_back(std::move(*keyframe));
    contents.finished = false;
  } else if (type == "resume") {
    ++contents.resumes;
    contents.finished = false;
  } else if (type == "end") {
    contents.finished = true;
  } else {
    return Status::error(where + ": unknown record type '" + type +
                         "' (written by a newer sonoshape? use that one to resume)");
  }
  return Status::ok();
}

}  // namespace

Result<JournalContents> read_journal(const fs::path& path) {
  Result<std::string> read = read_input_file(path, "the journal");
  if (!read)
    return Status::error(read.message() + (std::filesystem::exists(path)
                                               ? ""
                                               : " (was the scan started with this --out?)"));
  const std::string bytes = std::move(*read);
  const std::string name = path.string();
  if (bytes.size() < kHeaderBytes || bytes.compare(0, sizeof(kMagic), kMagic, sizeof(kMagic)) != 0)
    return Status::error(name + ": not a sonoshape scan journal (no SNSHJRNL header)");
  if (const std::uint32_t version = get_u32(bytes, 8); version != kVersion)
    return Status::error(name + ": journal version " + std::to_string(version) +
                         "; this sonoshape reads version 1 (use the sonoshape that wrote it)");
  JournalContents contents;
  std::size_t at = kHeaderBytes;
  for (std::size_t record = 0; at < bytes.size(); ++record) {
    const std::string where =
        name + ", record " + std::to_string(record) + " at byte " + std::to_string(at);
    const std::size_t left = bytes.size() - at;
    const std::uint32_t length = left >= kRecordHeaderBytes ? get_u32(bytes, at) : 0;
    const bool cut_short = left < kRecordHeaderBytes || left - kRecordHeaderBytes < length;
    const bool bad_length = !cut_short && (length == 0 || length > kMaxRecordBytes);
    const bool bad_crc =
        !cut_short && !bad_length &&
        crc32_of(bytes.data() + at + kRecordHeaderBytes, length) != get_u32(bytes, at + 4);
    const bool last = cut_short || at + kRecordHeaderBytes + length == bytes.size();
    if (cut_short || ((bad_length || bad_crc) && (last || all_zero(bytes, at)))) {
      // A crash while this record was written: it never counted; the scan goes on without it.
      contents.torn_tail = where + ": torn (" + std::to_string(left) + " bytes" +
                           (cut_short ? ", cut short" : ", checksum mismatch") +
                           "), dropped; the keyframes before it are kept";
      break;
    }
    if (bad_length || bad_crc)
      return Status::error(where + ": " + (bad_length ? "impossible length" : "checksum mismatch") +
                           " with records after it: the file is corrupt, not torn by a crash");
    if (Status applied =
            apply_record(bytes.substr(at + kRecordHeaderBytes, length), where, contents);
        !applied)
      return applied;
    if (record == 0 && contents.arguments.empty())
      return Status::error(where + ": the first record must be the scan's (its arguments)");
    at += kRecordHeaderBytes + length;
  }
  contents.valid_bytes = at;
  return contents;
}

KeyframeJournal::KeyframeJournal(fs::path path, int fd, std::uint64_t size, JournalIo io)
    : path_(std::move(path)), fd_(fd), size_(size), io_(std::move(io)) {
  if (!io_.write_at) io_.write_at = posix_write_at;
}

KeyframeJournal::~KeyframeJournal() {
  if (fd_ >= 0) ::close(fd_);
}

Result<std::unique_ptr<KeyframeJournal>> KeyframeJournal::create(
    const fs::path& path, const std::vector<std::string>& arguments, JournalIo io) {
  // The working directory: a resume reads the arguments' relative paths from there, wherever
  // it is started.
  std::error_code ec;
  const fs::path working_directory = fs::current_path(ec);
  json record = {{"type", "scan"}, {"version", kVersion}, {"arguments", arguments}};
  if (!ec) record["working_directory"] = working_directory.string();
  const std::string start = header_bytes() + encode_record(record);
  if (Status written = write_file_atomically(path, start); !written) return written;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0)
    return Status::error("cannot open the journal " + path.string() + ": " + system_reason(errno));
  return std::unique_ptr<KeyframeJournal>(
      new KeyframeJournal(path, fd, start.size(), std::move(io)));
}

Result<std::unique_ptr<KeyframeJournal>> KeyframeJournal::reopen(const fs::path& path,
                                                                 const JournalContents& contents,
                                                                 std::int64_t after_frame,
                                                                 JournalIo io) {
  const std::uint64_t valid_bytes = contents.valid_bytes;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0)
    return Status::error("cannot open the journal " + path.string() + ": " + system_reason(errno));
  // Cut off a torn tail: the next record must follow the last whole one.
  if (::ftruncate(fd, static_cast<off_t>(valid_bytes)) != 0) {
    const int error = errno;
    ::close(fd);
    return Status::error("cannot cut the torn tail of " + path.string() + ": " +
                         system_reason(error));
  }
  std::unique_ptr<KeyframeJournal> journal(
      new KeyframeJournal(path, fd, valid_bytes, std::move(io)));
  journal->written_ = contents.keyframes.size();
  journal->pending_.push_back(encode_record({{"type", "resume"}, {"after_frame", after_frame}}));
  if (Status written = journal->write_pending(); !written) return written;
  return journal;
}

Status KeyframeJournal::write_pending() {
  std::string bytes;
  for (const std::string& record : pending_) bytes += record;
  int error = io_.write_at(fd_, bytes.data(), bytes.size(), size_);
  if (!error) error = sync_fd(fd_);
  if (error) {
    // Back to the last whole record: a later retry must not follow half of one.
    [[maybe_unused]] const int cut = ::ftruncate(fd_, static_cast<off_t>(size_));
    return Status::error(
        "cannot append to the journal " + path_.string() + ": " + system_reason(error) +
        "; keyframes held in memory until it works again: " + std::to_string(pending_keyframes_));
  }
  size_ += bytes.size();
  written_ += pending_keyframes_;
  pending_.clear();
  pending_keyframes_ = 0;
  return Status::ok();
}

Status KeyframeJournal::append(const JournalKeyframe& keyframe) {
  return append(std::vector<JournalKeyframe>{keyframe});
}

Status KeyframeJournal::append(const std::vector<JournalKeyframe>& keyframes) {
  for (const JournalKeyframe& keyframe : keyframes) {
    auto slice = write_slice_json(keyframe.slice);
    if (!slice) return Status::error("journal " + path_.string() + ": " + slice.message());
    json record = {{"type", "keyframe"},
                   {"n", written_ + pending_keyframes_},
                   {"frame", keyframe.frame_index},
                   {"plane", plane_json(keyframe.plane)}};
    record["slice"] = json::parse(*slice);
    pending_.push_back(encode_record(record));
    ++pending_keyframes_;
  }
  return write_pending();
}

Status KeyframeJournal::finish(std::size_t slices) {
  pending_.push_back(encode_record({{"type", "end"}, {"slices", slices}}));
  return write_pending();
}

Status write_file_atomically(const fs::path& path, const std::string& text) {
  const fs::path partial = path.parent_path() / (".partial-" + path.filename().string());
  const int fd = ::open(partial.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    return Status::error("cannot create " + partial.string() + ": " + system_reason(errno));
  int error = posix_write_at(fd, text.data(), text.size(), 0);
  if (!error) error = sync_fd(fd);
  ::close(fd);
  if (error) {
    std::error_code ignored;
    fs::remove(partial, ignored);  // a full disk wants its space back
    return Status::error("cannot write " + path.string() + ": " + system_reason(error));
  }
  std::error_code ec;
  fs::rename(partial, path, ec);
  if (ec)
    return Status::error("cannot move " + partial.string() + " to " + path.string() + ": " +
                         ec.message());
  return sync_directory(path.parent_path());
}

Status sync_and_rename(const fs::path& from, const fs::path& to) {
  const int fd = ::open(from.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::error("cannot open " + from.string() + ": " + system_reason(errno));
  const int error = sync_fd(fd);
  ::close(fd);
  if (error) return Status::error("cannot sync " + from.string() + ": " + system_reason(error));
  std::error_code ec;
  fs::rename(from, to, ec);
  if (ec)
    return Status::error("cannot move " + from.string() + " to " + to.string() + ": " +
                         ec.message());
  return sync_directory(to.parent_path());
}

}  // namespace sonoshape::scan
