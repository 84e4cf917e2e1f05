#include "seqloc/raster/png_codec.hpp"

#include <csetjmp>
#include <cstring>

#include <png.h>
#include <zlib.h>

namespace seqloc::raster {
namespace {

struct WriteState {
  std::vector<std::uint8_t>* out;
};

void write_to_vector(png_structp png, png_bytep data, png_size_t length) {
  auto* state = static_cast<WriteState*>(png_get_io_ptr(png));
  state->out->insert(state->out->end(), data, data + length);
}

void flush_nothing(png_structp) {}

struct ReadState {
  std::span<const std::uint8_t> blob;
  std::size_t offset = 0;
};

void read_from_span(png_structp png, png_bytep data, png_size_t length) {
  auto* state = static_cast<ReadState*>(png_get_io_ptr(png));
  if (state->offset + length > state->blob.size()) png_error(png, "truncated PNG data");
  std::memcpy(data, state->blob.data() + state->offset, length);
  state->offset += length;
}

void error_to_longjmp(png_structp png, png_const_charp message) {
  auto* text = static_cast<std::string*>(png_get_error_ptr(png));
  if (text) *text = message;
  png_longjmp(png, 1);
}

void ignore_warning(png_structp, png_const_charp) {}

std::vector<std::uint8_t> encode(const void* pixels, int width, int height, int color_type, int bit_depth,
                                 int bytes_per_pixel, int filter) {
  std::vector<std::uint8_t> out;
  out.reserve(4096);
  std::string error;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &error, error_to_longjmp, ignore_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, &info);
    throw PngError("cannot initialise the PNG encoder");
  }
  std::vector<png_bytep> rows(static_cast<std::size_t>(height));
  WriteState state{&out};
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw PngError("PNG encoding failed: " + error);
  }
  png_set_write_fn(png, &state, write_to_vector, flush_nothing);
  png_set_compression_level(png, 1);
  png_set_compression_strategy(png, Z_DEFAULT_STRATEGY);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, filter);
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height), bit_depth, color_type,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);  // PNG stores big-endian samples
  const auto stride = static_cast<std::size_t>(width) * static_cast<std::size_t>(bytes_per_pixel);
  for (int r = 0; r < height; ++r) {
    rows[static_cast<std::size_t>(r)] =
        const_cast<png_bytep>(static_cast<const std::uint8_t*>(pixels) + static_cast<std::size_t>(r) * stride);
  }
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return out;
}

}  // namespace

std::vector<std::uint8_t> encode_png_rgb8(std::span<const std::uint8_t> rgb, int width, int height) {
  if (rgb.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3) {
    throw PngError("encode_png_rgb8: buffer size does not match the image size");
  }
  return encode(rgb.data(), width, height, PNG_COLOR_TYPE_RGB, 8, 3, PNG_FILTER_NONE);
}

std::vector<std::uint8_t> encode_png_gray16(std::span<const std::uint16_t> values, int width, int height) {
  if (values.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height)) {
    throw PngError("encode_png_gray16: buffer size does not match the image size");
  }
  // The SUB filter turns the smooth distance ramps into small residuals that deflate well.
  return encode(values.data(), width, height, PNG_COLOR_TYPE_GRAY, 16, 2, PNG_FILTER_SUB);
}

PngImage decode_png(std::span<const std::uint8_t> blob, const std::string& what) {
  if (blob.size() < 8 || png_sig_cmp(blob.data(), 0, 8) != 0) throw PngError(what + ": not a PNG image");
  std::string error;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &error, error_to_longjmp, ignore_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw PngError(what + ": cannot initialise the PNG decoder");
  }
  PngImage image;
  ReadState state{blob, 0};
  std::vector<png_bytep> rows;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw PngError(what + ": corrupt PNG: " + error);
  }
  png_set_read_fn(png, &state, read_from_span);
  png_read_info(png, info);
  const auto width = png_get_image_width(png, info);
  const auto height = png_get_image_height(png, info);
  const int color_type = png_get_color_type(png, info);
  const int depth = png_get_bit_depth(png, info);
  if (width == 0 || height == 0 || width > 8192 || height > 8192) png_error(png, "implausible image size");
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (depth < 8) png_set_expand(png);
  if (depth == 16) png_set_swap(png);
  png_read_update_info(png, info);
  image.width = static_cast<int>(width);
  image.height = static_cast<int>(height);
  image.channels = png_get_channels(png, info);
  image.bit_depth = png_get_bit_depth(png, info);
  const std::size_t stride = png_get_rowbytes(png, info);
  rows.resize(height);
  std::uint8_t* base = nullptr;
  if (image.bit_depth == 16) {
    image.pixels16.resize(stride / 2 * height);
    base = reinterpret_cast<std::uint8_t*>(image.pixels16.data());
  } else {
    image.pixels8.resize(stride * height);
    base = image.pixels8.data();
  }
  for (png_uint_32 r = 0; r < height; ++r) rows[r] = base + r * stride;
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return image;
}

}  // namespace seqloc::raster
