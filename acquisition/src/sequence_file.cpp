#include "sonoshape/acquisition/sequence_file.hpp"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include "sequence_text.hpp"
#include "sonoshape/core/input_file.hpp"

namespace sonoshape::acquisition {
namespace {

using detail::fail;
using detail::kFramePrefix;
using detail::kTransformSuffix;
using detail::parse_number;
using detail::split_frame_key;
using detail::split_words;
using detail::trim;

constexpr std::string_view kStatusSuffix = "TransformStatus";

// Header fields whose values follow from the pixel data; the writer recomputes them.
constexpr std::array<std::string_view, 8> kLayoutKeys = {
    "ObjectType",         "NDims",   "BinaryData", "BinaryDataByteOrderMSB", "CompressedData",
    "CompressedDataSize", "DimSize", "ElementType"};

bool is_layout_key(std::string_view key) {
  return key == "ElementDataFile" ||
         std::find(kLayoutKeys.begin(), kLayoutKeys.end(), key) != kLayoutKeys.end();
}

bool ends_with(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

std::string format_number(double value) {
  std::array<char, 32> buffer{};
  const auto [end, ec] = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  if (ec != std::errc()) return "nan";
  return std::string(buffer.data(), end);
}

bool is_true(std::string_view value) {
  const std::string_view v = trim(value);
  return v == "True" || v == "true" || v == "TRUE" || v == "1";
}

std::string frame_key(std::size_t k, std::string_view name) {
  std::array<char, 24> digits{};
  std::snprintf(digits.data(), digits.size(), "%04zu", k);
  return std::string(kFramePrefix) + digits.data() + "_" + std::string(name);
}

}  // namespace

std::optional<std::string> find_field(const FieldList& fields, std::string_view key) {
  for (const auto& [k, v] : fields)
    if (k == key) return v;
  return std::nullopt;
}

void set_field(FieldList& fields, std::string_view key, std::string value) {
  for (auto& [k, v] : fields)
    if (k == key) {
      v = std::move(value);
      return;
    }
  fields.emplace_back(std::string(key), std::move(value));
}

std::string format_matrix(const Eigen::Matrix4d& matrix) {
  std::string text;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      if (!text.empty()) text += ' ';
      text += format_number(matrix(r, c));
    }
  return text;
}

std::optional<Eigen::Matrix4d> parse_matrix(std::string_view text) {
  const auto words = split_words(text);
  if (words.size() != 16) return std::nullopt;
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i) {
    const auto value = parse_number<double>(words[static_cast<std::size_t>(i)]);
    if (!value) return std::nullopt;
    m(i / 4, i % 4) = *value;
  }
  return m;
}

void SequenceFile::add_frame(GreyImage image, FieldList frame_fields) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != static_cast<std::size_t>(image.width) * image.height)
    throw std::invalid_argument("SequenceFile::add_frame: empty or inconsistent image");
  if (images_.empty()) {
    width_ = image.width;
    height_ = image.height;
  } else if (image.width != width_ || image.height != height_) {
    throw std::invalid_argument("SequenceFile::add_frame: frame " + std::to_string(images_.size()) +
                                " is " + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + ", the sequence is " +
                                std::to_string(width_) + "x" + std::to_string(height_));
  }
  images_.push_back(std::move(image));
  frame_fields_.push_back(std::move(frame_fields));
}

std::optional<double> SequenceFile::timestamp_s(std::size_t k) const {
  const auto text = frame_field(k, "Timestamp");
  if (!text) return std::nullopt;
  return parse_number<double>(*text);
}

Frame SequenceFile::frame(std::size_t k) const {
  Frame f;
  f.image = image(k);
  f.timestamp_s = timestamp_s(k).value_or(0.0);
  f.index = static_cast<std::int64_t>(k);
  return f;
}

Result<Eigen::Matrix4d> SequenceFile::transform(std::string_view name, std::size_t k) const {
  const std::string key = std::string(name) + std::string(kTransformSuffix);
  if (k >= frame_count())
    return Status::error("sequence file: frame " + std::to_string(k) + " does not exist (" +
                         std::to_string(frame_count()) + " frames)");
  const auto text = frame_field(k, key);
  if (!text) {
    std::string known;
    for (const auto& n : transform_names()) known += (known.empty() ? "" : ", ") + n;
    return Status::error("sequence file: frame " + std::to_string(k) + " has no " + key +
                         " field (transforms in the file: " + (known.empty() ? "none" : known) +
                         ")");
  }
  const auto matrix = parse_matrix(*text);
  if (!matrix)
    return Status::error("sequence file: frame " + std::to_string(k) + " field " + key +
                         " is not 16 numbers (row-major 4x4): '" + *text + "'");
  return *matrix;
}

TrackingStatus SequenceFile::transform_status(std::string_view name, std::size_t k) const {
  const auto status = frame_field(k, std::string(name) + std::string(kStatusSuffix));
  if (status) return trim(*status) == "OK" ? TrackingStatus::kValid : TrackingStatus::kInvalid;
  return transform(name, k) ? TrackingStatus::kValid : TrackingStatus::kInvalid;
}

void SequenceFile::set_transform(std::string_view name, std::size_t k,
                                 const Eigen::Matrix4d& matrix, TrackingStatus status) {
  set_frame_field(k, std::string(name) + std::string(kTransformSuffix), format_matrix(matrix));
  set_frame_field(k, std::string(name) + std::string(kStatusSuffix),
                  status == TrackingStatus::kValid ? "OK" : "INVALID");
}

std::vector<std::string> SequenceFile::transform_names() const {
  std::vector<std::string> names;
  for (const FieldList& fields : frame_fields_)
    for (const auto& [key, value] : fields) {
      if (!ends_with(key, kTransformSuffix)) continue;
      std::string name = key.substr(0, key.size() - kTransformSuffix.size());
      if (std::find(names.begin(), names.end(), name) == names.end())
        names.push_back(std::move(name));
    }
  return names;
}

namespace detail {

InflateResult inflate_buffer(const std::uint8_t* in, std::size_t in_size, std::uint8_t* out,
                             std::size_t out_size, int window_bits) {
  z_stream stream{};
  if (inflateInit2(&stream, window_bits) != Z_OK) return {Z_MEM_ERROR, 0};
  stream.next_in = const_cast<Bytef*>(in);
  stream.next_out = out;
  std::size_t in_left = in_size, out_left = out_size;
  constexpr std::size_t kChunk = 1u << 30;  // zlib counts in uInt: feed large buffers in pieces
  const bool gzip_members = window_bits > MAX_WBITS;
  int rc = Z_OK;
  for (;;) {
    if (stream.avail_in == 0 && in_left > 0) {
      stream.avail_in = static_cast<uInt>(std::min(in_left, kChunk));
      in_left -= stream.avail_in;
    }
    if (stream.avail_out == 0 && out_left > 0) {
      stream.avail_out = static_cast<uInt>(std::min(out_left, kChunk));
      out_left -= stream.avail_out;
    }
    rc = inflate(&stream, Z_NO_FLUSH);
    if (rc == Z_OK) continue;
    // gzip allows members one after another (as `cat a.gz b.gz`); anything else after the end
    // (padding) is ignored, as the MetaImage reader ignores bytes past CompressedDataSize.
    if (rc == Z_STREAM_END && gzip_members && stream.avail_in >= 2 &&
        (stream.avail_out > 0 || out_left > 0) && stream.next_in[0] == 0x1f &&
        stream.next_in[1] == 0x8b) {
      inflateReset(&stream);
      continue;
    }
    if (rc == Z_BUF_ERROR &&
        ((stream.avail_in == 0 && in_left == 0) || (stream.avail_out == 0 && out_left == 0)))
      break;
    if (rc != Z_BUF_ERROR) break;
  }
  // total_out restarts with each gzip member; the output pointer does not.
  const auto produced = static_cast<std::size_t>(stream.next_out - out);
  inflateEnd(&stream);
  return {rc, produced};
}

}  // namespace detail

namespace detail {

Result<std::string> read_element_data_file(const std::filesystem::path& header,
                                           const std::string& name) {
  const std::string what = "ElementDataFile = " + name;
  // Only a plain file name: a header must not reach outside its own folder.
  if (name.empty() || name == "LIST" || name.find_first_of("/\\%") != std::string::npos ||
      name == "." || name == ".." || std::filesystem::path(name).is_absolute())
    return fail(header, what + " is not a file name in the header's folder",
                "sonoshape reads the pixels from one file next to the header (e.g. "
                "'ElementDataFile = sweep.raw'), or after it ('ElementDataFile = LOCAL'); lists, "
                "patterns and paths are not read");
  const std::filesystem::path data_path = header.parent_path() / name;
  std::ifstream in(data_path, std::ios::binary);
  if (!in) {
    std::string similar;
    std::error_code ec;
    const std::string stem = std::filesystem::path(name).stem().string();
    for (const auto& entry : std::filesystem::directory_iterator(
             header.parent_path().empty() ? std::filesystem::path(".") : header.parent_path(), ec))
      if (entry.path().stem().string() == stem && entry.path() != header)
        similar += (similar.empty() ? "" : ", ") + entry.path().filename().string();
    return fail(header, what + ": cannot open " + data_path.string(),
                similar.empty() ? "copy the pixel file next to the header"
                                : "files there with that stem: " + similar +
                                      "; if one is the pixel file, write its name in "
                                      "ElementDataFile");
  }
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return fail(header, what + ": read error in " + data_path.string(), "");
  return bytes;
}

}  // namespace detail

namespace {

// The 'Key = value' lines of a MetaImage header up to ElementDataFile: the global fields and
// the per-frame ones (Seq_FrameNNNN_Key). `pos` ends where the pixel data begins.
Status parse_metaimage_header(const std::filesystem::path& path, const std::string& data,
                              FieldList& fields, std::map<std::size_t, FieldList>& frame_fields,
                              std::size_t& pos) {
  std::size_t line_number = 0;
  while (pos < data.size()) {
    const std::size_t eol = data.find('\n', pos);
    const std::size_t end = eol == std::string::npos ? data.size() : eol;
    const std::string_view line = trim(std::string_view(data).substr(pos, end - pos));
    pos = eol == std::string::npos ? data.size() : eol + 1;
    ++line_number;
    if (line.empty()) continue;
    const std::string where = "header line " + std::to_string(line_number);
    const std::size_t eq = line.find('=');
    if (eq == std::string_view::npos) {
      return fail(path, where + " '" + std::string(line.substr(0, 60)) + "' is not 'Key = value'",
                  "sonoshape reads MetaImage sequences (.mha: 'Key = value' lines ending with "
                  "'ElementDataFile = LOCAL') and NRRD sequences (.nrrd: first line NRRD0004)");
    }
    const std::string key(trim(line.substr(0, eq)));
    std::string value(trim(line.substr(eq + 1)));
    if (key.empty()) return fail(path, where + " has no key before '='", "");
    if (const auto frame_key = split_frame_key(key)) {
      set_field(frame_fields[frame_key->first], frame_key->second, std::move(value));
      continue;
    }
    set_field(fields, key, value);
    if (key == "ElementDataFile") return Status::ok();
  }
  return fail(path, "the header has no 'ElementDataFile = LOCAL' line",
              "the file is truncated or not a MetaImage sequence");
}

// What a MetaImage header says of its pixels.
struct MetaImageLayout {
  std::size_t width = 0, height = 0, frames = 0;
  std::string dim_text;  // DimSize as written, for messages
  bool compressed = false;
};

// NDims, DimSize, ElementType and ElementNumberOfChannels, checked: 8-bit grey frames whose
// per-frame fields name no frame beyond DimSize.
Result<MetaImageLayout> read_layout(const std::filesystem::path& path, const FieldList& fields,
                                    const std::map<std::size_t, FieldList>& frame_fields) {
  const auto ndims = parse_number<int>(find_field(fields, "NDims").value_or(""));
  if (!ndims || (*ndims != 2 && *ndims != 3))
    return fail(path, "NDims is '" + find_field(fields, "NDims").value_or("missing") + "'",
                "a tracked-frame sequence has 'NDims = 3' (or 2 for one frame)");
  const auto dim_text = find_field(fields, "DimSize");
  if (!dim_text) return fail(path, "DimSize is missing", "add 'DimSize = W H N'");
  const auto dim_words = split_words(*dim_text);
  std::array<long long, 3> dims{0, 0, 1};
  bool dims_ok = dim_words.size() == static_cast<std::size_t>(*ndims);
  for (std::size_t i = 0; dims_ok && i < dim_words.size(); ++i) {
    const auto v = parse_number<long long>(dim_words[i]);
    dims_ok = v && *v >= 0 && *v <= std::numeric_limits<int>::max();
    if (dims_ok) dims[i] = *v;
  }
  if (!dims_ok || dims[0] <= 0 || dims[1] <= 0)
    return fail(path,
                "DimSize = '" + *dim_text + "' is not " + std::to_string(*ndims) +
                    " non-negative integers with W, H > 0",
                "write it as 'DimSize = W H N' (width, height, frames)");
  const std::string element_type = find_field(fields, "ElementType").value_or("missing");
  if (element_type != "MET_UCHAR")
    return fail(path, "ElementType = " + element_type + " is not supported",
                "only 8-bit grey frames (MET_UCHAR) are; convert the sequence with PLUS "
                "EditSequenceFile or another tool");
  if (const auto channels = find_field(fields, "ElementNumberOfChannels");
      channels && *channels != "1")
    return fail(path, "ElementNumberOfChannels = " + *channels + " is not supported",
                "only single-channel (grey) frames are");
  MetaImageLayout layout;
  layout.width = static_cast<std::size_t>(dims[0]);
  layout.height = static_cast<std::size_t>(dims[1]);
  layout.frames = static_cast<std::size_t>(dims[2]);
  layout.dim_text = *dim_text;
  layout.compressed = is_true(find_field(fields, "CompressedData").value_or("False"));
  if (!frame_fields.empty() && frame_fields.rbegin()->first >= layout.frames)
    return fail(path,
                "per-frame field of frame " + std::to_string(frame_fields.rbegin()->first) +
                    " but DimSize says " + std::to_string(layout.frames) + " frames",
                "fix DimSize or remove the fields of the missing frames");
  return layout;
}

// Whether `available` bytes of pixel data can hold what the layout asks for, checked before
// anything is allocated: zlib's deflate expands at most 1032 times.
Status check_pixel_bytes(const std::filesystem::path& path, const MetaImageLayout& layout,
                         std::size_t available) {
  const std::size_t w = layout.width, h = layout.height, n = layout.frames;
  const std::size_t frame_bytes = w * h;  // below 2^62: W and H are at most 2^31 - 1
  constexpr std::size_t kMaxInflateRatio = 1032;
  const std::string size = std::to_string(w) + "x" + std::to_string(h) + "x" + std::to_string(n);
  if (layout.compressed && n > 0 && frame_bytes > (available * kMaxInflateRatio + 64) / n)
    return fail(path,
                "DimSize = '" + layout.dim_text + "' needs " + size + " bytes but only " +
                    std::to_string(available) +
                    " compressed bytes follow the header, which cannot hold them",
                "the file is truncated or DimSize is wrong");
  if (!layout.compressed && n > 0 && frame_bytes > available / n)  // W*H*N may overflow
    return fail(path,
                "the raw pixel data has " + std::to_string(available) + " bytes, DimSize needs " +
                    size + " (frame " + std::to_string(available / frame_bytes) + " is incomplete)",
                "the file is truncated or DimSize is wrong");
  return Status::ok();
}

// The compressed pixels, inflated to exactly the layout's W x H x N bytes.
Result<std::vector<std::uint8_t>> inflate_pixels(const std::filesystem::path& path,
                                                 const FieldList& fields,
                                                 const MetaImageLayout& layout,
                                                 std::string_view pixel_data) {
  const std::size_t frame_bytes = layout.width * layout.height;
  const std::size_t total = frame_bytes * layout.frames;
  std::size_t compressed_size = pixel_data.size();
  if (const auto text = find_field(fields, "CompressedDataSize")) {
    const auto size = parse_number<std::size_t>(*text);
    if (!size) return fail(path, "CompressedDataSize = '" + *text + "' is not a byte count", "");
    if (*size > pixel_data.size())
      return fail(path,
                  "CompressedDataSize is " + std::to_string(*size) + " bytes but only " +
                      std::to_string(pixel_data.size()) + " follow the header",
                  "the file is truncated; copy it again");
    compressed_size = *size;
  }
  // One spare output byte tells "exactly DimSize" from "more than DimSize".
  std::vector<std::uint8_t> pixels(total + 1);
  const auto [rc, produced] =
      detail::inflate_buffer(reinterpret_cast<const std::uint8_t*>(pixel_data.data()),
                             compressed_size, pixels.data(), pixels.size(), MAX_WBITS);
  pixels.resize(total);
  if (rc != Z_STREAM_END && rc != Z_BUF_ERROR)
    return fail(path,
                "the compressed pixel data is corrupt (zlib error " + std::to_string(rc) +
                    " in frame " + std::to_string(produced / frame_bytes) + ")",
                "the file is damaged; copy it again");
  if (produced > total)
    return fail(path, "the pixel data holds more than DimSize (" + layout.dim_text + ") describes",
                "DimSize is wrong");
  if (produced < total)
    return fail(path,
                "the pixel data decompresses to " + std::to_string(produced) +
                    " bytes, DimSize needs " + std::to_string(total) + " (frame " +
                    std::to_string(produced / frame_bytes) + " is incomplete)",
                "the file is truncated or DimSize is wrong");
  return pixels;
}

}  // namespace

Result<SequenceFile> read_sequence_file(const std::filesystem::path& path) {
  Result<std::string> bytes = read_input_file(path, "sequence file");
  if (!bytes) return bytes.status();
  const std::string data = std::move(*bytes);
  // The content decides, not the name: PLUS writes both formats as .igs.*, Slicer as .seq.nrrd,
  // and users rename files.
  if (std::string_view(data).substr(0, 7) == "NRRD000")
    return detail::read_nrrd_sequence(path, data);

  // MetaImage.
  SequenceFile file;
  std::map<std::size_t, FieldList> frame_fields;
  std::size_t pos = 0;
  if (Status header = parse_metaimage_header(path, data, file.fields_, frame_fields, pos); !header)
    return header;
  // A .mhd names its pixel file (.raw, or .zraw when compressed) beside it.
  std::string external;
  const std::string data_file = file.field("ElementDataFile").value_or("LOCAL");
  if (data_file != "LOCAL") {
    auto read = detail::read_element_data_file(path, data_file);
    if (!read) return read.status();
    external = std::move(*read);
  }
  const std::string_view pixel_data =
      data_file == "LOCAL" ? std::string_view(data).substr(pos) : std::string_view(external);
  const Result<MetaImageLayout> layout = read_layout(path, file.fields_, frame_fields);
  if (!layout) return layout.status();
  if (Status fits = check_pixel_bytes(path, *layout, pixel_data.size()); !fits) return fits;
  const std::size_t frame_bytes = layout->width * layout->height;
  std::vector<std::uint8_t> pixels;
  if (layout->compressed) {
    Result<std::vector<std::uint8_t>> inflated =
        inflate_pixels(path, file.fields_, *layout, pixel_data);
    if (!inflated) return inflated.status();
    pixels = std::move(*inflated);
  } else {
    pixels.assign(pixel_data.begin(),
                  pixel_data.begin() + static_cast<std::ptrdiff_t>(frame_bytes * layout->frames));
  }
  file.width_ = static_cast<int>(layout->width);
  file.height_ = static_cast<int>(layout->height);
  file.images_.reserve(layout->frames);
  file.frame_fields_.resize(layout->frames);
  for (std::size_t k = 0; k < layout->frames; ++k) {
    GreyImage image;
    image.width = file.width_;
    image.height = file.height_;
    const auto first = pixels.begin() + static_cast<std::ptrdiff_t>(k * frame_bytes);
    image.pixels.assign(first, first + static_cast<std::ptrdiff_t>(frame_bytes));
    file.images_.push_back(std::move(image));
  }
  for (auto& [k, fields] : frame_fields) file.frame_fields_[k] = std::move(fields);
  return file;
}

Status write_sequence_file(const SequenceFile& file, const std::filesystem::path& path,
                           const SequenceWriteOptions& options) {
  if (file.frame_count() == 0)
    return fail(path, "no frames to write", "a MetaImage sequence needs at least one frame");
  const std::size_t frame_bytes = static_cast<std::size_t>(file.width()) * file.height();

  std::vector<std::uint8_t> compressed;
  if (options.compress) {
    z_stream stream{};
    if (deflateInit(&stream, std::clamp(options.compression_level, 1, 9)) != Z_OK)
      return fail(path, "zlib deflateInit failed", "");
    compressed.resize(deflateBound(&stream, static_cast<uLong>(frame_bytes * file.frame_count())));
    stream.next_out = compressed.data();
    stream.avail_out = static_cast<uInt>(
        std::min<std::size_t>(compressed.size(), std::numeric_limits<uInt>::max()));
    for (std::size_t k = 0; k < file.frame_count(); ++k) {
      stream.next_in = const_cast<Bytef*>(file.image(k).pixels.data());
      stream.avail_in = static_cast<uInt>(frame_bytes);
      const bool last = k + 1 == file.frame_count();
      const int rc = deflate(&stream, last ? Z_FINISH : Z_NO_FLUSH);
      if ((last && rc != Z_STREAM_END) || (!last && rc != Z_OK)) {
        deflateEnd(&stream);
        return fail(path, "zlib deflate failed on frame " + std::to_string(k), "");
      }
    }
    compressed.resize(stream.total_out);
    deflateEnd(&stream);
  }

  std::map<std::string, std::string> layout;
  layout["ObjectType"] = file.field("ObjectType").value_or("Image");
  layout["NDims"] = "3";
  layout["BinaryData"] = "True";
  layout["BinaryDataByteOrderMSB"] = "False";
  layout["CompressedData"] = options.compress ? "True" : "False";
  if (options.compress) layout["CompressedDataSize"] = std::to_string(compressed.size());
  layout["DimSize"] = std::to_string(file.width()) + " " + std::to_string(file.height()) + " " +
                      std::to_string(file.frame_count());
  layout["ElementType"] = "MET_UCHAR";

  std::ostringstream header;
  for (std::string_view key : kLayoutKeys)
    if (!file.field(key) && layout.count(std::string(key)))
      header << key << " = " << layout[std::string(key)] << '\n';
  for (const auto& [key, value] : file.fields()) {
    if (key == "ElementDataFile") continue;
    if (is_layout_key(key)) {
      if (layout.count(key)) header << key << " = " << layout[key] << '\n';
      continue;
    }
    header << key << " = " << value << '\n';
  }
  for (std::size_t k = 0; k < file.frame_count(); ++k)
    for (const auto& [name, value] : file.frame_fields(k))
      header << frame_key(k, name) << " = " << value << '\n';
  header << "ElementDataFile = LOCAL\n";

  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out)
    return fail(path, "cannot create it", "check that the directory exists and is writable");
  const std::string text = header.str();
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  if (options.compress) {
    out.write(reinterpret_cast<const char*>(compressed.data()),
              static_cast<std::streamsize>(compressed.size()));
  } else {
    for (std::size_t k = 0; k < file.frame_count(); ++k)
      out.write(reinterpret_cast<const char*>(file.image(k).pixels.data()),
                static_cast<std::streamsize>(frame_bytes));
  }
  out.close();
  // errno says which limit it was: ENOSPC (a full disk) or EFBIG (ulimit -f).
  if (!out)
    return fail(path, std::string("cannot write it: ") + std::strerror(errno),
                "free disk space or raise the file-size limit, then run again");
  return Status::ok();
}

Status require_tracking(const SequenceFile& file, const std::filesystem::path& path,
                        std::string_view probe_transform) {
  const auto names = file.transform_names();
  if (std::find(names.begin(), names.end(), probe_transform) != names.end()) return Status::ok();
  std::string known;
  for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
  const std::string field = std::string(probe_transform) + std::string(kTransformSuffix);
  if (file.field("ImageToReferenceTransform") && names.empty())
    return fail(path,
                "an image-only sequence (3D Slicer .seq.nrrd): its frames have no per-frame "
                "tracking (" +
                    field +
                    "), only one image geometry for all frames (ImageToReferenceTransform, "
                    "from space directions/origin), so every frame would lie in one plane",
                "Slicer keeps the probe's tracking in separate transform sequences, which "
                "sonoshape does not read; record the sweep with PLUS (fCal or PlusServer "
                "capture) as .igs.mha or .igs.nrrd, which store " +
                    field + " per frame");
  return fail(path,
              "no frame has a " + field +
                  " field (transforms in the file: " + (known.empty() ? "none" : known) + ")",
              "a tracked sweep needs the probe's pose per frame: record it with the tracker "
              "(PLUS Seq_FrameNNNN_" +
                  field + ")");
}

namespace {

// PLUS's 2D orientation codes (US_IMG_ORIENT_*): how the image's x and y run against the
// transducer's marked side and the far field. sonoshape implements MF, PLUS's default.
bool is_plus_orientation(std::string_view code) {
  if (code.size() != 2 && code.size() != 3) return false;
  if (code[0] != 'M' && code[0] != 'U') return false;
  if (code[1] != 'F' && code[1] != 'N') return false;
  return code.size() == 2 || code[2] == 'A' || code[2] == 'D';
}

// The farthest a pose may place the probe from the tracker's origin: 1 km.
constexpr double kMaxPoseDistanceMm = 1e6;

// A tracker pose maps rigidly: rotation part orthonormal with determinant +1 (to 1e-3, what
// six-digit matrices in files keep), last row 0 0 0 1.
std::optional<std::string> rigid_problem(const Eigen::Matrix4d& m) {
  if (!m.allFinite()) return "it holds NaN or infinite numbers";
  if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9)
    return "its last row is not 0 0 0 1";
  const Eigen::Matrix3d r = m.block<3, 3>(0, 0);
  const double off = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (off > 1e-3 || r.determinant() < 0.0) {
    std::ostringstream text;
    text << "its rotation part is not a rotation (R^T R differs from the identity by " << off
         << ", determinant " << r.determinant() << ")";
    return text.str();
  }
  // A tracker's volume is metres across: a pose a kilometre away is in other units or damaged,
  // and would put the slice where no bounds can follow it.
  if (const double distance_mm = m.block<3, 1>(0, 3).norm(); distance_mm > kMaxPoseDistanceMm) {
    std::ostringstream text;
    text << "its translation is " << distance_mm << " mm from the tracker's origin (more than "
         << kMaxPoseDistanceMm << " mm: not millimetres, or a damaged matrix)";
    return text.str();
  }
  return std::nullopt;
}

}  // namespace

Status check_tracked_sweep(const SequenceFile& file, const std::filesystem::path& path,
                           std::string_view probe_transform) {
  return check_tracked_sweep(
      file, path,
      std::vector<std::string>{std::string(probe_transform), std::string("ReferenceToTracker")});
}

Status check_tracked_sweep(const SequenceFile& file, const std::filesystem::path& path,
                           const std::vector<std::string>& pose_transforms) {
  if (const auto orientation = file.field("UltrasoundImageOrientation")) {
    const std::string code(trim(*orientation));
    if (!is_plus_orientation(code))
      return fail(path, "UltrasoundImageOrientation = '" + code + "' is not a PLUS orientation",
                  "write MF (or MFA), the orientation of PLUS recordings: x from the marked "
                  "side, y into the far field");
    if (code.substr(0, 2) != "MF")
      return fail(path, "UltrasoundImageOrientation = " + code + " is not supported",
                  "the frames must be flipped to MF first (sonoshape segment and scan do "
                  "this on reading: acquisition::reorient_to_mf)");
  }
  for (std::size_t k = 0; k < file.frame_count(); ++k) {
    const std::string frame = "frame " + std::to_string(k);
    if (const auto text = file.frame_field(k, "Timestamp")) {
      const auto t = parse_number<double>(*text);
      if (!t || !std::isfinite(*t))
        return fail(
            path, frame + ": Timestamp = '" + std::string(trim(*text)) + "' is not a finite number",
            "write the frame's acquisition time in seconds");
    }
    for (const std::string& name : pose_transforms) {
      if (!file.frame_field(k, name + std::string(kTransformSuffix))) continue;
      if (file.transform_status(name, k) != TrackingStatus::kValid) continue;  // not used
      const auto matrix = file.transform(name, k);
      if (!matrix)
        return fail(path,
                    frame + ": " + name + std::string(kTransformSuffix) + " is not 16 numbers",
                    "write a row-major 4x4 matrix");
      if (const auto problem = rigid_problem(*matrix))
        return fail(path, frame + ": " + name + std::string(kTransformSuffix) + ": " + *problem,
                    "a tracker pose is a rotation and a translation: fix the matrix, or mark "
                    "the frame's " +
                        name + "TransformStatus = INVALID to skip it");
    }
  }
  return Status::ok();
}

}  // namespace sonoshape::acquisition
