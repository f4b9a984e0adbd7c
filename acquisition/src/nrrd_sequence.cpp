// NRRD sequences: PLUS `.igs.nrrd` (per-frame `Seq_FrameNNNN_<Name>:=value` key/values) and
// 3D Slicer `.seq.nrrd` volume sequences (a `list` axis with `axis <A> index values`), read into
// the same SequenceFile as a MetaImage sequence. What is and is not read: sequence_file.hpp and
// docs/formats/sequences.md.
#include <zlib.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cctype>
#include <fstream>
#include <limits>
#include <map>

#include "integer_samples.hpp"
#include "sequence_text.hpp"

namespace sonoshape::acquisition::detail {
namespace {

// NRRD fields that describe how the samples are stored; they are consumed, not kept as fields
// (a MetaImage written from the sequence must not claim `encoding: gzip`).
constexpr std::array<std::string_view, 10> kLayoutFields = {
    "dimension", "type",      "sizes",     "encoding",  "endian",
    "kinds",     "data file", "byte skip", "line skip", "block size"};

// One header line: a field ("name: value") or a key/value ("key:=value").
struct HeaderEntry {
  std::string name;
  std::string value;
  std::size_t line = 0;
};

struct NrrdHeader {
  std::vector<HeaderEntry> fields;      ///< names lower-case, spelling variants unified
  std::vector<HeaderEntry> key_values;  ///< keys as written
  std::size_t data_offset = 0;          ///< first byte after the blank line (attached data)
  bool has_blank_line = false;

  const HeaderEntry* field(std::string_view name) const {
    for (const HeaderEntry& e : fields)
      if (e.name == name) return &e;
    return nullptr;
  }
  const HeaderEntry* key_value(std::string_view key) const {
    for (const HeaderEntry& e : key_values)
      if (e.name == key) return &e;
    return nullptr;
  }
};

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// The NRRD format allows "datafile", "byteskip", ... for the two-word field names.
std::string canonical_field_name(std::string_view name) {
  std::string n = lower(name);
  if (n == "datafile") return "data file";
  if (n == "byteskip") return "byte skip";
  if (n == "lineskip") return "line skip";
  if (n == "blocksize") return "block size";
  return n;
}

std::string where(const HeaderEntry& e) {
  return "header line " + std::to_string(e.line) + " '" + e.name + "'";
}

Result<NrrdHeader> parse_header(const std::filesystem::path& path, const std::string& data) {
  NrrdHeader header;
  std::size_t pos = 0;
  std::size_t line_number = 0;
  while (pos < data.size()) {
    const std::size_t eol = data.find('\n', pos);
    const std::size_t end = eol == std::string::npos ? data.size() : eol;
    std::string_view line = std::string_view(data).substr(pos, end - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = eol == std::string::npos ? data.size() : eol + 1;
    ++line_number;
    if (line_number == 1) {
      if (line.size() != 8 || line.substr(0, 7) != "NRRD000" || line[7] < '1' || line[7] > '5')
        return fail(path,
                    "header line 1 '" + std::string(line.substr(0, 40)) +
                        "' is not a NRRD magic (NRRD0001 .. NRRD0005)",
                    "the file is damaged or not NRRD");
      continue;
    }
    if (line.empty()) {  // the blank line ends the header; attached data follows it
      header.data_offset = pos;
      header.has_blank_line = true;
      break;
    }
    if (line.front() == '#') continue;
    // A key/value's key may not contain ":=", a field's name no ": "; the first of the two
    // separators decides.
    const std::size_t kv = line.find(":=");
    std::size_t colon = line.find(": ");
    if (colon == std::string_view::npos && line.back() == ':') colon = line.size() - 1;
    HeaderEntry entry;
    entry.line = line_number;
    if (kv != std::string_view::npos && (colon == std::string_view::npos || kv < colon)) {
      entry.name = std::string(trim(line.substr(0, kv)));
      entry.value = std::string(trim(line.substr(kv + 2)));
      header.key_values.push_back(std::move(entry));
    } else if (colon != std::string_view::npos) {
      entry.name = canonical_field_name(trim(line.substr(0, colon)));
      entry.value = std::string(trim(line.substr(colon + 1)));
      // The NRRD format gives each field once: of two 'sizes:', which one the pixels follow
      // is anyone's guess.
      if (const HeaderEntry* first = header.field(entry.name))
        return fail(
            path, where(entry) + " repeats the field of header line " + std::to_string(first->line),
            "a NRRD header gives each field once; remove one of the two lines");
      header.fields.push_back(std::move(entry));
    } else {
      return fail(path,
                  "header line " + std::to_string(line_number) + " '" +
                      std::string(line.substr(0, 60)) +
                      "' is neither 'field: value' nor 'key:=value'",
                  "fix the line or remove it (NRRD comments start with '#')");
    }
  }
  return header;
}

// The sample type, as far as frames of grey levels need it.
struct SampleType {
  int bytes = 0;
  bool is_signed = false;
};

std::optional<SampleType> sample_type(std::string_view name) {
  const std::string n = lower(name);
  for (std::string_view u8 : {"uchar", "unsigned char", "uint8", "uint8_t"})
    if (n == u8) return SampleType{1, false};
  for (std::string_view s8 : {"signed char", "int8", "int8_t"})
    if (n == s8) return SampleType{1, true};
  for (std::string_view u16 :
       {"ushort", "unsigned short", "unsigned short int", "uint16", "uint16_t"})
    if (n == u16) return SampleType{2, false};
  for (std::string_view s16 :
       {"short", "short int", "signed short", "signed short int", "int16", "int16_t"})
    if (n == s16) return SampleType{2, true};
  return std::nullopt;
}

// "(1,0,0) (0,1,0) none" -> one entry per axis: the vector, or none.
std::optional<std::vector<std::optional<Eigen::VectorXd>>> parse_vectors(std::string_view text) {
  std::vector<std::optional<Eigen::VectorXd>> out;
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && (text[i] == ' ' || text[i] == '\t')) ++i;
    if (i >= text.size()) break;
    if (text.substr(i, 4) == "none") {
      out.emplace_back(std::nullopt);
      i += 4;
      continue;
    }
    if (text[i] != '(') return std::nullopt;
    const std::size_t close = text.find(')', i);
    if (close == std::string_view::npos) return std::nullopt;
    std::vector<double> values;
    std::string_view inside = text.substr(i + 1, close - i - 1);
    while (true) {
      const std::size_t comma = inside.find(',');
      const auto value = parse_number<double>(inside.substr(0, comma));
      if (!value) return std::nullopt;
      values.push_back(*value);
      if (comma == std::string_view::npos) break;
      inside.remove_prefix(comma + 1);
    }
    out.emplace_back(
        Eigen::Map<Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size())));
    i = close + 1;
  }
  return out;
}

// Axis roles: the two image axes, the frame axis and the other (size-1) spatial axis.
struct Axes {
  std::vector<long long> sizes;
  std::vector<std::string> kinds;  ///< as written; empty strings when the header has no kinds
  int image_i = -1;                ///< image columns
  int image_j = -1;                ///< image rows
  int normal = -1;                 ///< a third spatial axis of size 1, if any
  int frames = -1;                 ///< the list axis, if any
};

bool is_spatial_kind(std::string_view kind) {
  return kind.empty() || kind == "domain" || kind == "space";
}

// The axes' sizes and kinds ('dimension', 'sizes', 'kinds'), checked against each other.
Result<Axes> read_sizes_and_kinds(const std::filesystem::path& path, const NrrdHeader& header) {
  const HeaderEntry* dimension_field = header.field("dimension");
  const HeaderEntry* sizes_field = header.field("sizes");
  if (!dimension_field || !sizes_field)
    return fail(
        path,
        std::string("the header has no '") + (dimension_field ? "sizes" : "dimension") + "' field",
        "a NRRD sequence needs 'dimension' and 'sizes' (e.g. 'sizes: 820 616 97')");
  const auto dimension = parse_number<int>(dimension_field->value);
  if (!dimension || *dimension < 2 || *dimension > 16)
    return fail(path, where(*dimension_field) + " is '" + dimension_field->value + "'",
                "a frame sequence has dimension 2 (one frame), 3 (PLUS) or 4 (Slicer)");
  Axes axes;
  for (std::string_view word : split_words(sizes_field->value)) {
    const auto size = parse_number<long long>(word);
    if (!size || *size < 1 || *size > std::numeric_limits<int>::max())
      return fail(path,
                  where(*sizes_field) + " '" + sizes_field->value +
                      "' holds a size that is not a positive integer",
                  "write one positive size per axis");
    axes.sizes.push_back(*size);
  }
  if (axes.sizes.size() != static_cast<std::size_t>(*dimension))
    return fail(path,
                where(*sizes_field) + " has " + std::to_string(axes.sizes.size()) +
                    " sizes, dimension is " + std::to_string(*dimension),
                "give one size per axis");
  axes.kinds.assign(axes.sizes.size(), "");
  if (const HeaderEntry* kinds = header.field("kinds")) {
    const auto words = split_words(kinds->value);
    if (words.size() != axes.sizes.size())
      return fail(path,
                  where(*kinds) + " has " + std::to_string(words.size()) + " kinds, dimension is " +
                      std::to_string(*dimension),
                  "give one kind per axis");
    for (std::size_t a = 0; a < words.size(); ++a) axes.kinds[a] = std::string(words[a]);
  } else if (*dimension > 2) {
    return fail(path, "the header has no 'kinds' field, so the frame axis is unknown",
                "add e.g. 'kinds: domain domain list' (PLUS) or 'kinds: domain domain domain "
                "list' (Slicer)");
  }
  return axes;
}

// The frame axis (kind list or time) into axes.frames, and the spatial axes; other kinds must
// be one sample (a colour or vector axis is refused).
Result<std::vector<int>> spatial_axes(const std::filesystem::path& path, Axes& axes) {
  std::vector<int> spatial;
  for (int a = 0; a < static_cast<int>(axes.sizes.size()); ++a) {
    const std::string kind = lower(axes.kinds[static_cast<std::size_t>(a)]);
    const long long size = axes.sizes[static_cast<std::size_t>(a)];
    if (kind == "list" || kind == "time") {
      if (axes.frames >= 0)
        return fail(path,
                    "axes " + std::to_string(axes.frames) + " and " + std::to_string(a) +
                        " are both of kind list/time",
                    "a sequence has one frame axis");
      axes.frames = a;
    } else if (is_spatial_kind(kind)) {
      spatial.push_back(a);
    } else if (size != 1) {
      return fail(path,
                  "axis " + std::to_string(a) + " is of kind '" +
                      axes.kinds[static_cast<std::size_t>(a)] + "' with size " +
                      std::to_string(size),
                  "only single-channel grey frames are read: convert the images to scalar "
                  "(grey) volumes first, e.g. with Slicer's Vector to Scalar Volume");
    }
  }
  return spatial;
}

Result<Axes> find_axes(const std::filesystem::path& path, const NrrdHeader& header) {
  Result<Axes> read = read_sizes_and_kinds(path, header);
  if (!read) return read;
  Axes axes = std::move(*read);
  const Result<std::vector<int>> spatial = spatial_axes(path, axes);
  if (!spatial) return spatial.status();
  const std::string& sizes_text = header.field("sizes")->value;
  // The image plane: the first two spatial axes longer than one sample; a third one must be one
  // sample thick (a 2D ultrasound frame stored as a W x H x 1 volume).
  std::vector<int> plane;
  for (int a : *spatial)
    if (axes.sizes[static_cast<std::size_t>(a)] > 1) plane.push_back(a);
  if (plane.size() > 2)
    return fail(path, "each frame is a 3D volume (sizes " + sizes_text + ")",
                "only 2D frames (one slice thick) are read, as a tracked ultrasound probe gives");
  for (int a : *spatial)
    if (plane.size() < 2 && std::find(plane.begin(), plane.end(), a) == plane.end())
      plane.push_back(a);
  if (plane.size() < 2)
    return fail(path, "fewer than two image axes (kinds: domain/space) in sizes " + sizes_text,
                "a frame needs width and height");
  std::sort(plane.begin(), plane.end());
  axes.image_i = plane[0];
  axes.image_j = plane[1];
  for (int a : *spatial)
    if (a != axes.image_i && a != axes.image_j) axes.normal = a;
  return axes;
}

// gzip (or zlib) data -> exactly `total` bytes.
Result<std::vector<std::uint8_t>> decode_gzip(const std::filesystem::path& path,
                                              std::string_view source,
                                              const std::filesystem::path& source_path,
                                              std::size_t total) {
  // zlib expands at most 1032 times: a 'sizes' the data cannot hold is refused before the
  // samples are allocated (sizes: 512 512 1000000 over a few bytes).
  constexpr std::size_t kMaxInflateRatio = 1032;
  if (total > source.size() * kMaxInflateRatio + 64)
    return fail(path,
                "'sizes' and type need " + std::to_string(total) + " bytes but only " +
                    std::to_string(source.size()) + " gzip bytes are in " + source_path.string() +
                    ", which cannot hold them",
                "the file is truncated or 'sizes' is wrong");
  // One spare byte tells "exactly sizes" from "more than sizes".
  std::vector<std::uint8_t> samples(total + 1);
  const auto [rc, produced] =
      inflate_buffer(reinterpret_cast<const std::uint8_t*>(source.data()), source.size(),
                     samples.data(), samples.size(), MAX_WBITS + 32);
  samples.resize(total);
  if (rc != Z_STREAM_END && rc != Z_BUF_ERROR)
    return fail(path,
                "the gzip data in " + source_path.string() + " is corrupt (zlib error " +
                    std::to_string(rc) + " after " + std::to_string(produced) + " bytes)",
                "the file is damaged; copy it again");
  if (produced > total)
    return fail(path, "the data holds more samples than 'sizes' describes", "'sizes' is wrong");
  if (produced < total)
    return fail(path,
                "the gzip data decompresses to " + std::to_string(produced) +
                    " bytes, sizes and type need " + std::to_string(total),
                "the file is truncated or 'sizes' is wrong");
  return samples;
}

// Text samples -> `sample_bytes` bytes each, in the byte order to_grey expects.
Result<std::vector<std::uint8_t>> decode_text(const std::filesystem::path& path,
                                              std::string_view source, std::size_t sample_count,
                                              int sample_bytes, bool big_endian,
                                              bool quote_samples) {
  std::vector<std::uint8_t> samples;
  // At most one sample per two characters ("1 "): a lying 'sizes' must not allocate.
  samples.reserve(std::min(sample_count, source.size() / 2 + 1) *
                  static_cast<std::size_t>(sample_bytes));
  std::string text(source);
  for (char& c : text)
    if (c == '\n' || c == '\r' || c == ',') c = ' ';
  std::size_t count = 0;
  for (std::string_view word : split_words(text)) {
    const auto value = parse_number<long long>(word);
    if (!value || *value < -32768 || *value > 65535)
      return fail(path,
                  "text sample " + std::to_string(count) +
                      (quote_samples ? " '" + std::string(word.substr(0, 20)) + "'" : "") +
                      " is not an integer sample",
                  "the data does not match 'type'");
    const auto bits = static_cast<std::uint16_t>(*value);
    const auto lo = static_cast<std::uint8_t>(bits & 0xff);
    const auto hi = static_cast<std::uint8_t>(bits >> 8);
    if (sample_bytes == 1) {
      samples.push_back(lo);
    } else {
      samples.push_back(big_endian ? hi : lo);
      samples.push_back(big_endian ? lo : hi);
    }
    ++count;
  }
  if (count != sample_count)
    return fail(path,
                "the text data has " + std::to_string(count) + " samples, sizes need " +
                    std::to_string(sample_count),
                "the file is truncated or 'sizes' is wrong");
  return samples;
}

// The detached data file `name` of the header `path`: only a file in the header's own folder or
// below it. A sequence file comes from anyone (a colleague, a download); followed anywhere, its
// `data file` would turn /etc/passwd or /proc/self/environ into pixels that the scan segments
// and streams. Absolute names and '..' are refused as written; a symbolic link that leads out
// of the folder is refused by comparing canonical paths.
Result<std::filesystem::path> detached_data_path(const std::filesystem::path& path,
                                                 const HeaderEntry& field,
                                                 const std::string& name) {
  namespace fs = std::filesystem;
  const std::string fix = "keep the data file in the header's folder and name it relative to it";
  const fs::path relative(name);
  if (relative.is_absolute() || relative.has_root_name() || relative.has_root_directory())
    return fail(path, where(field) + " '" + name + "' is an absolute path",
                fix + " (a detached file is read only from there)");
  for (const fs::path& part : relative)
    if (part == "..")
      return fail(path, where(field) + " '" + name + "' leads out of the header's folder ('..')",
                  fix);
  std::error_code ec;
  const fs::path folder = fs::canonical(fs::absolute(path, ec).parent_path(), ec);
  if (ec)
    return fail(path, "cannot resolve the header's folder (" + ec.message() + ")",
                "check that the folder exists and can be read");
  const fs::path joined = folder / relative;
  if (!fs::exists(joined, ec))
    return fail(path, where(field) + ": cannot open " + joined.string(),
                "keep the data file next to the header, or fix the name");
  const fs::path resolved = fs::canonical(joined, ec);
  if (ec)
    return fail(path,
                where(field) + ": cannot resolve " + joined.string() + " (" + ec.message() + ")",
                fix);
  const auto [end, unused] =
      std::mismatch(folder.begin(), folder.end(), resolved.begin(), resolved.end());
  if (end != folder.end()) {
    const std::string escape = " '" + name + "' is a link that leads out of the header's folder";
    return fail(path, where(field) + escape + " (to " + resolved.string() + ")", fix);
  }
  return resolved;
}

// Reads the bytes that hold the samples: after the header, or from `data file`, after the
// line skip, decoded. Fails naming the field; never quotes a detached file's content (the
// file may not be the user's to read out).
// The bytes of a detached data file ('data file'): one regular file, resolved beside the header.
Result<std::string> read_detached(const std::filesystem::path& path, const HeaderEntry& data_file,
                                  std::filesystem::path& source_path) {
  const auto words = split_words(data_file.value);
  if (words.size() != 1 || data_file.value.find('%') != std::string::npos ||
      data_file.value.rfind("LIST", 0) == 0)
    return fail(path, where(data_file) + " '" + data_file.value + "' names several files",
                "only one detached data file is read; join the parts into one file");
  auto resolved = detached_data_path(path, data_file, std::string(words[0]));
  if (!resolved) return resolved.status();
  source_path = *resolved;
  // A device or a pipe (/dev/zero, /dev/stdin) would be read without end or block forever.
  std::error_code ec;
  if (!std::filesystem::is_regular_file(source_path, ec))
    return fail(path,
                where(data_file) + ": " + source_path.string() +
                    " is not a regular file (a device, a pipe or a folder)",
                "name the file that holds the samples");
  std::ifstream in(source_path, std::ios::binary);
  if (!in)
    return fail(path, where(data_file) + ": cannot open " + source_path.string(),
                "keep the data file next to the header, or fix the name");
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Drops the 'line skip' lines from the front of `source`.
Status skip_lines(const std::filesystem::path& path, const NrrdHeader& header,
                  const std::filesystem::path& source_path, std::string_view& source) {
  const HeaderEntry* line_skip = header.field("line skip");
  if (!line_skip) return Status::ok();
  const auto lines = parse_number<long long>(line_skip->value);
  if (!lines || *lines < 0)
    return fail(path, where(*line_skip) + " is '" + line_skip->value + "'", "give a line count");
  for (long long k = 0; k < *lines; ++k) {
    const std::size_t eol = source.find('\n');
    if (eol == std::string_view::npos)
      return fail(path, where(*line_skip) + ": " + source_path.string() + " has fewer lines",
                  "fix 'line skip'");
    source.remove_prefix(eol + 1);
  }
  return Status::ok();
}

// 'byte skip' (raw encoding only; -1: the samples end the file).
Result<long long> byte_skip(const std::filesystem::path& path, const NrrdHeader& header,
                            const std::string& encoding) {
  const HeaderEntry* field = header.field("byte skip");
  if (!field) return 0LL;
  const auto value = parse_number<long long>(field->value);
  if (!value || *value < -1)
    return fail(path, where(*field) + " is '" + field->value + "'", "give a byte count or -1");
  if (*value != 0 && encoding != "raw")
    return fail(path, where(*field) + " with encoding " + encoding + " is not supported",
                "byte skip is read with raw encoding only");
  return *value;
}

Result<std::vector<std::uint8_t>> read_samples(const std::filesystem::path& path,
                                               const NrrdHeader& header, const std::string& data,
                                               std::size_t sample_count, int sample_bytes,
                                               bool big_endian) {
  const std::size_t total = sample_count * static_cast<std::size_t>(sample_bytes);
  // The samples' file.
  std::string detached;
  std::string_view source;
  std::filesystem::path source_path = path;
  if (const HeaderEntry* data_file = header.field("data file")) {
    Result<std::string> read = read_detached(path, *data_file, source_path);
    if (!read) return read.status();
    detached = std::move(*read);
    source = detached;
  } else {
    if (!header.has_blank_line)
      return fail(path,
                  "the header has neither a 'data file' field nor a blank line before the data",
                  "the file is truncated or its header was cut");
    source = std::string_view(data).substr(header.data_offset);
  }
  if (Status skipped = skip_lines(path, header, source_path, source); !skipped) return skipped;
  const HeaderEntry* encoding_field = header.field("encoding");
  if (!encoding_field)
    return fail(path, "the header has no 'encoding' field",
                "add 'encoding: raw' or 'encoding: gzip'");
  const std::string encoding = lower(encoding_field->value);
  const Result<long long> skip = byte_skip(path, header, encoding);
  if (!skip) return skip.status();
  if (encoding == "raw") {
    const std::size_t offset = *skip == -1 ? (source.size() >= total ? source.size() - total : 0)
                                           : static_cast<std::size_t>(*skip);
    const std::size_t available = source.size() > offset ? source.size() - offset : 0;
    if (available < total)
      return fail(path,
                  "the raw data in " + source_path.string() + " has " + std::to_string(available) +
                      " bytes, sizes and type need " + std::to_string(total),
                  "the file is truncated or 'sizes' is wrong");
    const auto* first = reinterpret_cast<const std::uint8_t*>(source.data() + offset);
    return std::vector<std::uint8_t>(first, first + total);
  }
  if (encoding == "gzip" || encoding == "gz") return decode_gzip(path, source, source_path, total);
  if (encoding == "text" || encoding == "txt" || encoding == "ascii")
    return decode_text(path, source, sample_count, sample_bytes, big_endian,
                       /*quote_samples=*/source_path == path);
  return fail(path, where(*encoding_field) + " '" + encoding_field->value + "' is not supported",
              "re-save it with encoding raw or gzip (Slicer: Save with compression; unu "
              "save -e gzip)");
}

// Samples -> 8-bit grey levels. 16-bit samples are accepted when every value fits 0..255 (an
// 8-bit image saved as short), so no grey level is scaled or clipped.
Result<std::vector<std::uint8_t>> to_grey(const std::filesystem::path& path,
                                          std::vector<std::uint8_t> samples, SampleType type,
                                          bool big_endian, const HeaderEntry& type_field) {
  if (type.bytes == 1 && !type.is_signed) return samples;
  const IntegerSamples stored{type.bytes, type.is_signed, big_endian};
  std::vector<std::uint8_t> grey(samples.size() / static_cast<std::size_t>(type.bytes));
  if (const auto s = narrow_to_8_bits(samples.data(), grey.size(), stored, grey.data()))
    return fail(path,
                where(type_field) + " is " + type_field.value + " and sample " +
                    std::to_string(*s) + " is " +
                    std::to_string(integer_sample(samples.data(), *s, stored)) + ", outside 0..255",
                "only 8-bit grey levels are read; rescale the images to unsigned char "
                "(e.g. Slicer's Cast Scalar Volume) and save again");
  return grey;
}

// PLUS's per-frame field, with the image status under the name its MetaImage writer uses.
std::optional<std::pair<std::size_t, std::string>> plus_frame_key(std::string_view key) {
  auto frame_key = split_frame_key(key);
  // PLUS's NRRD writer calls the image status "Status", its MetaImage writer "ImageStatus".
  if (frame_key && frame_key->second == "Status") frame_key->second = "ImageStatus";
  return frame_key;
}

// "axis 3 item 5 AcquisitionTime" -> (5, "AcquisitionTime") when the axis is `frame_axis`.
std::optional<std::pair<std::size_t, std::string>> slicer_item_key(std::string_view key,
                                                                   int frame_axis) {
  const auto words = split_words(key);
  if (words.size() < 5 || words[0] != "axis" || words[2] != "item") return std::nullopt;
  if (parse_number<int>(words[1]) != frame_axis) return std::nullopt;
  const auto item = parse_number<std::size_t>(words[3]);
  if (!item) return std::nullopt;
  const std::size_t name_start = words[4].data() - key.data();
  return std::make_pair(*item, std::string(key.substr(name_start)));
}

// Slicer stores text index values URL-encoded ("%20" for a space).
std::string url_decode(std::string_view text) {
  std::string out;
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '%' && i + 2 < text.size() &&
        std::isxdigit(static_cast<unsigned char>(text[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(text[i + 2]))) {
      out += static_cast<char>(std::stoi(std::string(text.substr(i + 1, 2)), nullptr, 16));
      i += 2;
    } else {
      out += text[i];
    }
  }
  return out;
}

// PLUS's key/value names of its MetaImage fields.
std::string global_key_name(const std::string& key) {
  if (key == "ultrasound image orientation") return "UltrasoundImageOrientation";
  if (key == "ultrasound image type") return "UltrasoundImageType";
  return key;
}

// ImageToReference (pixel (i, j, 0) -> mm in the header's 3D space) from `space directions` and
// `space origin`; none when the header has no 3D space geometry for the image axes.
Result<std::optional<Eigen::Matrix4d>> image_to_reference(const std::filesystem::path& path,
                                                          const NrrdHeader& header,
                                                          const Axes& axes) {
  const HeaderEntry* directions_field = header.field("space directions");
  const HeaderEntry* origin_field = header.field("space origin");
  if (!directions_field || !origin_field) return std::optional<Eigen::Matrix4d>();
  const auto directions = parse_vectors(directions_field->value);
  if (!directions || directions->size() != axes.sizes.size())
    return fail(path, where(*directions_field) + " '" + directions_field->value + "'",
                "give one '(x,y,z)' or 'none' per axis");
  const auto origin = parse_vectors(origin_field->value);
  if (!origin || origin->size() != 1 || !origin->front())
    return fail(path, where(*origin_field) + " '" + origin_field->value + "'",
                "write it as '(x,y,z)'");
  // PLUS writes a 2D space ((1,0) (0,1) none): the pixel grid itself, no placement in 3D.
  if (origin->front()->size() != 3) return std::optional<Eigen::Matrix4d>();
  const auto& di = (*directions)[static_cast<std::size_t>(axes.image_i)];
  const auto& dj = (*directions)[static_cast<std::size_t>(axes.image_j)];
  if (!di || !dj || di->size() != 3 || dj->size() != 3)
    return fail(path,
                where(*directions_field) + " gives no 3D direction for the image axes " +
                    std::to_string(axes.image_i) + " and " + std::to_string(axes.image_j),
                "give '(x,y,z)' for each image axis and 'none' for the list axis");
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.block<3, 1>(0, 0) = *di;
  m.block<3, 1>(0, 1) = *dj;
  const Eigen::Vector3d normal = Eigen::Vector3d(*di).cross(Eigen::Vector3d(*dj));
  if (!(normal.norm() > 0.0))
    return fail(path, where(*directions_field) + ": the image axes are parallel",
                "the directions of the image axes must differ");
  Eigen::Vector3d third = normal.normalized() * std::sqrt(di->norm() * dj->norm());
  if (axes.normal >= 0)
    if (const auto& dk = (*directions)[static_cast<std::size_t>(axes.normal)];
        dk && dk->size() == 3)
      third = *dk;
  m.block<3, 1>(0, 2) = third;
  m.block<3, 1>(0, 3) = *origin->front();
  return std::optional<Eigen::Matrix4d>(m);
}

// The key/values split into per-frame fields (PLUS's Seq_Frame keys, Slicer's per-item
// attributes and index values) and global ones.
struct CollectedFields {
  std::vector<FieldList> frames;
  FieldList globals;
};

Result<CollectedFields> collect_fields(const std::filesystem::path& path, const NrrdHeader& header,
                                       int frame_axis, std::size_t n) {
  CollectedFields out;
  out.frames.resize(n);
  std::vector<FieldList>& frame_fields = out.frames;
  FieldList& globals = out.globals;
  const HeaderEntry* index_values = nullptr;
  const HeaderEntry* index_type = nullptr;
  const std::string index_prefix = "axis " + std::to_string(frame_axis) + " index ";
  for (const HeaderEntry& kv : header.key_values) {
    auto frame_key = plus_frame_key(kv.name);
    if (!frame_key) frame_key = slicer_item_key(kv.name, frame_axis);
    if (frame_key) {
      if (frame_key->first >= n)
        return fail(path,
                    where(kv) + " is a field of frame " + std::to_string(frame_key->first) +
                        " but the sequence has " + std::to_string(n) + " frames",
                    "fix 'sizes' or remove the fields of the missing frames");
      set_field(frame_fields[frame_key->first], frame_key->second, kv.value);
      continue;
    }
    if (frame_axis >= 0 && kv.name == index_prefix + "values") {
      index_values = &kv;
      continue;
    }
    if (frame_axis >= 0 && kv.name == index_prefix + "type") index_type = &kv;
    set_field(globals, global_key_name(kv.name), kv.value);
  }
  if (index_values) {
    const auto values = split_words(index_values->value);
    if (values.size() != n)
      return fail(path,
                  where(*index_values) + " lists " + std::to_string(values.size()) +
                      " values for " + std::to_string(n) + " frames",
                  "give one index value per frame");
    const bool numeric = !index_type || lower(index_type->value) == "numeric";
    for (std::size_t k = 0; k < n; ++k) {
      FieldList& fields = frame_fields[k];
      if (numeric) {
        const auto seconds = parse_number<double>(values[k]);
        if (!seconds)
          return fail(path,
                      where(*index_values) + " value " + std::to_string(k) + " '" +
                          std::string(values[k]) + "' is not a number",
                      "numeric index values are frame times in seconds");
        // A PLUS Timestamp of the frame, when there is one, is the frame's time.
        if (!find_field(fields, "Timestamp"))
          fields.insert(fields.begin(), {"Timestamp", std::string(values[k])});
      } else {
        fields.insert(fields.begin(), {"SequenceIndexValue", url_decode(values[k])});
      }
    }
  }

  return out;
}

}  // namespace

Result<SequenceFile> read_nrrd_sequence(const std::filesystem::path& path,
                                        const std::string& data) {
  auto parsed = parse_header(path, data);
  if (!parsed) return parsed.status();
  const NrrdHeader& header = *parsed;
  auto found_axes = find_axes(path, header);
  if (!found_axes) return found_axes.status();
  const Axes& axes = *found_axes;

  const HeaderEntry* type_field = header.field("type");
  if (!type_field) return fail(path, "the header has no 'type' field", "add e.g. 'type: uint8'");
  const auto type = sample_type(type_field->value);
  if (!type)
    return fail(path, where(*type_field) + " is '" + type_field->value + "'",
                "only 8-bit grey frames (uint8; 16-bit when every value is 0..255) are read; "
                "convert the images to unsigned char (e.g. Slicer's Cast Scalar Volume)");
  bool big_endian = false;
  if (type->bytes > 1) {
    const HeaderEntry* endian = header.field("endian");
    if (!endian || (lower(endian->value) != "little" && lower(endian->value) != "big"))
      return fail(path,
                  "'endian' is " + (endian ? "'" + endian->value + "'" : std::string("missing")),
                  "16-bit samples need 'endian: little' or 'endian: big'");
    big_endian = lower(endian->value) == "big";
  }

  // Checked before allocating: a damaged `sizes` must not ask for exabytes.
  constexpr std::size_t kMaxSamples = std::size_t{1} << 36;
  std::size_t sample_count = 1;
  for (long long s : axes.sizes) {
    if (static_cast<std::size_t>(s) > kMaxSamples / sample_count)
      return fail(path,
                  "sizes " + header.field("sizes")->value + " describe more than 2^36 samples",
                  "the header is damaged, or the sequence too large to read at once");
    sample_count *= static_cast<std::size_t>(s);
  }
  auto samples = read_samples(path, header, data, sample_count, type->bytes, big_endian);
  if (!samples) return samples.status();
  auto grey = to_grey(path, std::move(*samples), *type, big_endian, *type_field);
  if (!grey) return grey.status();

  // Strides of the axes (axis 0 varies fastest), so any axis order reads: PLUS and current
  // Slicer put the frame axis last, older Slicer first.
  std::vector<std::size_t> stride(axes.sizes.size(), 1);
  for (std::size_t a = 1; a < axes.sizes.size(); ++a)
    stride[a] = stride[a - 1] * static_cast<std::size_t>(axes.sizes[a - 1]);
  const int w = static_cast<int>(axes.sizes[static_cast<std::size_t>(axes.image_i)]);
  const int h = static_cast<int>(axes.sizes[static_cast<std::size_t>(axes.image_j)]);
  const std::size_t n =
      axes.frames >= 0 ? static_cast<std::size_t>(axes.sizes[static_cast<std::size_t>(axes.frames)])
                       : 1;
  const std::size_t si = stride[static_cast<std::size_t>(axes.image_i)];
  const std::size_t sj = stride[static_cast<std::size_t>(axes.image_j)];
  const std::size_t sk = axes.frames >= 0 ? stride[static_cast<std::size_t>(axes.frames)] : 0;

  auto fields = collect_fields(path, header, axes.frames, n);
  if (!fields) return fields.status();
  std::vector<FieldList>& frame_fields = fields->frames;

  const auto geometry = image_to_reference(path, header, axes);
  if (!geometry) return geometry.status();

  SequenceFile file;
  for (const HeaderEntry& f : header.fields)
    if (std::find(kLayoutFields.begin(), kLayoutFields.end(), f.name) == kLayoutFields.end())
      file.set_field(f.name, f.value);
  for (auto& [key, value] : fields->globals) file.set_field(key, std::move(value));
  if (*geometry) file.set_field("ImageToReferenceTransform", format_matrix(**geometry));
  for (std::size_t k = 0; k < n; ++k) {
    GreyImage image(w, h);
    const std::size_t base = k * sk;
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i)
        image.at(i, j) =
            (*grey)[base + static_cast<std::size_t>(j) * sj + static_cast<std::size_t>(i) * si];
    file.add_frame(std::move(image), std::move(frame_fields[k]));
  }
  return file;
}

}  // namespace sonoshape::acquisition::detail
