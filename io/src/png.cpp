#include <algorithm>
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <png.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/file_kind.h>
#include <avp/io/image_limits.h>
#include <avp/io/png.h>

namespace avp::io {

namespace {

struct FileCloser {
  void operator()(FILE* f) const {
    if (f != nullptr) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<FILE, FileCloser>;

// libpng reports errors through a callback that must not return; we longjmp back after storing
// the message.
struct ErrorState {
  std::string message;
};

void OnPngError(png_structp png, png_const_charp message) {
  auto* state = static_cast<ErrorState*>(png_get_error_ptr(png));
  if (state != nullptr) state->message = message;
  png_longjmp(png, 1);
}

void OnPngWarning(png_structp, png_const_charp) {}

void AppendToString(png_structp png, png_bytep data, png_size_t length) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  out->append(reinterpret_cast<const char*>(data), length);
}

void FlushNothing(png_structp) {}

// Encodes rows of `bytes_per_row` bytes in memory, then writes the file atomically
// (WriteFileAtomic: a temporary name, flushed, renamed); `color_type` and `bit_depth` as libpng
// expects. 16-bit samples are passed in host order and swapped by libpng (png_set_swap).
Status WriteRows(const std::filesystem::path& path, int width, int height, int color_type,
                 int bit_depth, const uint8_t* data, size_t bytes_per_row) {
  if (width <= 0 || height <= 0) {
    return InvalidArgumentError(
        fmt::format("cannot write empty image {}x{} to '{}'", width, height, path.string()));
  }
  ErrorState state;
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, OnPngError, OnPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr) {
    png_destroy_write_struct(&png, &info);
    return InternalError("libpng: out of memory creating a write struct");
  }
  std::vector<png_bytep> rows(static_cast<size_t>(height));
  for (int v = 0; v < height; ++v) {
    rows[v] = const_cast<png_bytep>(data + static_cast<size_t>(v) * bytes_per_row);
  }
  std::string encoded;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return InternalError(
        fmt::format("cannot encode PNG '{}': {}", path.string(), EscapeText(state.message)));
  }
  png_set_write_fn(png, &encoded, AppendToString, FlushNothing);
  png_set_compression_level(png, 3);
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height),
               bit_depth, color_type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return WriteFileAtomic(path, encoded, "PNG image");
}

struct Decoded {
  int width = 0;
  int height = 0;
  int channels = 0;
  int bit_depth = 0;
  std::vector<uint8_t> bytes;  // host-order samples
};

enum class Want { kRgb8, kGray8, kGray16 };

Result<Decoded> Decode(const std::filesystem::path& path, Want want) {
  // Missing, a folder, too large (max_file_bytes): told apart before opening.
  AVP_RETURN_IF_ERROR(CheckReadableFile(path, "PNG file").status());
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) {
    return IoError(
        fmt::format("cannot open '{}' for reading: {}", path.string(), std::strerror(errno)));
  }
  uint8_t signature[8] = {};
  const size_t got = std::fread(signature, 1, 8, file.get());
  if (got != 8 || png_sig_cmp(signature, 0, 8) != 0) {
    const std::string kind =
        DescribeFileKind(std::string_view(reinterpret_cast<const char*>(signature), got));
    return ParseError(fmt::format("'{}' is not a PNG file (bad signature{})", path.string(),
                                  kind.empty() ? "" : "; it is " + kind));
  }
  ErrorState state;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, OnPngError, OnPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr) {
    png_destroy_read_struct(&png, &info, nullptr);
    return InternalError("libpng: out of memory creating a read struct");
  }
  Decoded out;
  std::vector<png_bytep> rows;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return ParseError(
        fmt::format("corrupt or truncated PNG '{}': {}", path.string(), EscapeText(state.message)));
  }
  png_init_io(png, file.get());
  png_set_sig_bytes(png, 8);
  // Sides up to PNG's own maximum; the pixel budget below is what bounds the allocation.
  png_set_user_limits(png, PNG_UINT_31_MAX, PNG_UINT_31_MAX);
  png_read_info(png, info);
  // The header (IHDR) is read: its size is checked before any row is allocated or decoded.
  if (const Status size =
          CheckImageSize(png_get_image_width(png, info), png_get_image_height(png, info),
                         fmt::format("PNG image '{}'", path.string()));
      !size.ok()) {
    png_destroy_read_struct(&png, &info, nullptr);
    return size;
  }
  const int color_type = png_get_color_type(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  const bool is_gray =
      (color_type & PNG_COLOR_MASK_COLOR) == 0 && color_type != PNG_COLOR_TYPE_PALETTE;
  if (want == Want::kRgb8) {
    if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (is_gray) png_set_gray_to_rgb(png);
    if (bit_depth < 8) png_set_packing(png);
    if (bit_depth == 16) png_set_strip_16(png);
    if (color_type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
    if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_strip_alpha(png);
  } else {
    const int want_depth = want == Want::kGray8 ? 8 : 16;
    if (!is_gray || (color_type & PNG_COLOR_MASK_ALPHA) || bit_depth != want_depth) {
      png_destroy_read_struct(&png, &info, nullptr);
      return InvalidArgumentError(
          fmt::format("PNG '{}' has color type {} and bit depth {}; expected single-channel {}-bit",
                      path.string(), color_type, bit_depth, want_depth));
    }
    if (want_depth == 16) png_set_swap(png);
  }
  png_read_update_info(png, info);
  out.width = static_cast<int>(png_get_image_width(png, info));
  out.height = static_cast<int>(png_get_image_height(png, info));
  out.channels = png_get_channels(png, info);
  out.bit_depth = png_get_bit_depth(png, info);
  const size_t row_bytes = png_get_rowbytes(png, info);
  const size_t expected_row_bytes = static_cast<size_t>(out.width) *
                                    static_cast<size_t>(out.channels) *
                                    static_cast<size_t>(out.bit_depth / 8);
  if (out.bit_depth < 8 || row_bytes != expected_row_bytes) {
    png_destroy_read_struct(&png, &info, nullptr);
    return InternalError(fmt::format("PNG '{}' decodes to rows of {} bytes, expected {}",
                                     path.string(), row_bytes, expected_row_bytes));
  }
  out.bytes.resize(row_bytes * static_cast<size_t>(out.height));
  rows.resize(static_cast<size_t>(out.height));
  for (int v = 0; v < out.height; ++v) rows[v] = out.bytes.data() + v * row_bytes;
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return out;
}

}  // namespace

Status WritePngRgb8(const std::filesystem::path& path, const ImageRgb8& image) {
  return WriteRows(path, image.width(), image.height(), PNG_COLOR_TYPE_RGB, 8, image.data().data(),
                   static_cast<size_t>(image.width()) * 3);
}

Status WritePngGray8(const std::filesystem::path& path, const Image<uint8_t>& image) {
  return WriteRows(path, image.width(), image.height(), PNG_COLOR_TYPE_GRAY, 8, image.data().data(),
                   static_cast<size_t>(image.width()));
}

Status WritePngGray16(const std::filesystem::path& path, const Image<uint16_t>& image) {
  return WriteRows(path, image.width(), image.height(), PNG_COLOR_TYPE_GRAY, 16,
                   reinterpret_cast<const uint8_t*>(image.data().data()),
                   static_cast<size_t>(image.width()) * 2);
}

Result<ImageRgb8> ReadPngRgb8(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(Decoded d, Decode(path, Want::kRgb8));
  if (d.channels != 3 || d.bit_depth != 8) {
    return InternalError(fmt::format("PNG '{}' decoded to {} channels at {} bits", path.string(),
                                     d.channels, d.bit_depth));
  }
  ImageRgb8 image(d.width, d.height);
  std::copy(d.bytes.begin(), d.bytes.end(), image.data().begin());
  return image;
}

Result<Image<uint8_t>> ReadPngGray8(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(Decoded d, Decode(path, Want::kGray8));
  Image<uint8_t> image(d.width, d.height);
  std::copy(d.bytes.begin(), d.bytes.end(), image.data().begin());
  return image;
}

Result<Image<uint16_t>> ReadPngGray16(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(Decoded d, Decode(path, Want::kGray16));
  Image<uint16_t> image(d.width, d.height);
  std::memcpy(image.data().data(), d.bytes.data(), d.bytes.size());
  return image;
}

}  // namespace avp::io
