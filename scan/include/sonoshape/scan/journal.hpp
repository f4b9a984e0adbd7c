#pragma once
// The keyframe journal of a scan (docs/formats/scan-journal.md): every keyframe the
// reconstruction accepted, appended to `--out/scan.journal` as it is accepted (written, then
// fsync'd), so that a scan killed at any moment can be rebuilt by `sonoshape scan --resume DIR`.
// Each record carries its length and a CRC-32: a record torn by a crash is detected and dropped.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sonoshape/core/slice.hpp"
#include "sonoshape/core/status.hpp"
#include "sonoshape/tracking/keyframes.hpp"

namespace sonoshape::scan {

/// The journal's file name inside a scan's output directory.
inline constexpr const char* kJournalName = "scan.journal";

/// One accepted keyframe: the slice the reconstruction took, the source frame it came from and
/// the frame's plane (for the keyframe choice after a resume).
struct JournalKeyframe {
  std::int64_t frame_index = 0;  ///< Frame::index in its source
  tracking::FramePlane plane;    ///< image corners (mm, reference frame) and normal
  LabeledSlice slice;
};

/// What a journal holds.
struct JournalContents {
  /// The arguments of the scan command that started the journal (after `scan`).
  std::vector<std::string> arguments;
  /// The working directory of that command, against which its relative paths were read; none
  /// in journals written before it was recorded.
  std::optional<std::filesystem::path> working_directory;
  std::vector<JournalKeyframe> keyframes;  ///< in acceptance order
  bool finished = false;    ///< the scan wrote its end record (it was not interrupted)
  std::size_t resumes = 0;  ///< how many times it was resumed
  /// Bytes of whole, valid records (the header included): where the next record goes.
  std::uint64_t valid_bytes = 0;
  /// Set when the last record was torn (a crash while it was written): what was dropped.
  std::optional<std::string> torn_tail;
};

/// Reads a journal. A torn last record (cut short, or a checksum mismatch at the end of the
/// file) is dropped and described in `torn_tail`. Fails, naming the file, the record and its
/// byte offset, for a missing file, a wrong magic or version, a bad record followed by more
/// data (corruption, not a crash), or a record whose content is invalid.
Result<JournalContents> read_journal(const std::filesystem::path& path);

/// Where the journal's bytes go: POSIX write/fsync/ftruncate on a file descriptor by default;
/// tests replace it to fail like a full disk.
struct JournalIo {
  /// Writes `size` bytes at `offset`; returns 0 or an errno value (ENOSPC, EIO, EFBIG, ...).
  std::function<int(int fd, const char* data, std::size_t size, std::uint64_t offset)> write_at;
};

/// Appends keyframes to a journal file. A failed append (ENOSPC, EFBIG, EIO) truncates the
/// file back to its last whole record and keeps the keyframes in memory; each later append
/// retries them first, in order, so the file always holds a prefix of the accepted keyframes.
/// Not thread-safe (the pipeline's reconstruction thread owns it).
class KeyframeJournal {
 public:
  /// Creates (or replaces) `path` with its header and a record of `arguments`, synced to disk
  /// with its directory entry. Fails naming the file and the system's reason.
  static Result<std::unique_ptr<KeyframeJournal>> create(const std::filesystem::path& path,
                                                         const std::vector<std::string>& arguments,
                                                         JournalIo io = {});
  /// Opens an existing journal, whose whole records read_journal gave as `contents`, to go on
  /// appending after them (a torn tail is cut off), with a record of the resume after frame
  /// `after_frame`.
  static Result<std::unique_ptr<KeyframeJournal>> reopen(const std::filesystem::path& path,
                                                         const JournalContents& contents,
                                                         std::int64_t after_frame,
                                                         JournalIo io = {});
  ~KeyframeJournal();
  KeyframeJournal(const KeyframeJournal&) = delete;
  KeyframeJournal& operator=(const KeyframeJournal&) = delete;

  /// Appends `keyframe` (after any held back by earlier failures) and syncs it to disk. On
  /// failure the keyframes stay held; the message names the file and the reason.
  Status append(const JournalKeyframe& keyframe);
  /// Appends `keyframes` (one update's) with one write and one fsync; as append() otherwise.
  Status append(const std::vector<JournalKeyframe>& keyframes);
  /// Writes the end record (the scan finished normally), after any keyframes held back.
  Status finish(std::size_t slices);

  /// Keyframes held in memory because writing them failed.
  std::size_t pending() const { return pending_.size(); }
  /// Keyframes on disk.
  std::size_t written() const { return written_; }
  const std::filesystem::path& path() const { return path_; }

 private:
  KeyframeJournal(std::filesystem::path path, int fd, std::uint64_t size, JournalIo io);
  Status write_pending();
  std::filesystem::path path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;  // bytes of whole records on disk
  JournalIo io_;
  std::vector<std::string> pending_;  // encoded records not yet on disk
  std::size_t pending_keyframes_ = 0;
  std::size_t written_ = 0;
};

/// Writes `text` to `path` atomically: a temporary file in the same directory
/// (`.partial-<name>`), fsync'd, renamed over `path`, and the directory fsync'd, so that after a
/// crash `path` holds the old content or the new, whole. Fails naming the file and the reason
/// (ENOSPC: "No space left on device").
Status write_file_atomically(const std::filesystem::path& path, const std::string& text);

/// Makes a file written under a temporary name durable and moves it over `to`: fsync of the
/// file, rename, fsync of the directory.
Status sync_and_rename(const std::filesystem::path& from, const std::filesystem::path& to);

}  // namespace sonoshape::scan
