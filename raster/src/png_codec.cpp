#include "seqloc/raster/png_codec.hpp"

#include <csetjmp>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>

#include <libdeflate.h>
#include <png.h>

namespace seqloc::raster {
namespace {

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

// ---------------------------------------------------------------------------------------------
// The fast path: our own tiles (8-bit grey/RGB/RGBA or 16-bit grey, not interlaced) are written
// and read with libdeflate, which inflates and deflates two to three times faster than zlib;
// the PNG container around the zlib stream is a handful of chunks (PNG spec, ISO/IEC 15948).
// Anything else falls back to libpng.

constexpr std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

struct CompressorDeleter {
  void operator()(libdeflate_compressor* c) const { libdeflate_free_compressor(c); }
};
struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};

// Levels measured on north-Bayreuth tiles: for the class tiles (long runs) level 2 is both faster
// and smaller than level 1, whose matchfinder is slow on runs; for the distance tiles level 1 is
// fastest (higher levels shrink them by at most a third at twice the time).
libdeflate_compressor* thread_compressor(int level) {
  thread_local std::unique_ptr<libdeflate_compressor, CompressorDeleter> compressors[2] = {
      std::unique_ptr<libdeflate_compressor, CompressorDeleter>(libdeflate_alloc_compressor(1)),
      std::unique_ptr<libdeflate_compressor, CompressorDeleter>(libdeflate_alloc_compressor(2))};
  auto& compressor = compressors[level == 1 ? 0 : 1];
  if (!compressor) throw PngError("cannot allocate a deflate compressor");
  return compressor.get();
}

libdeflate_decompressor* thread_decompressor() {
  thread_local std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> decompressor(
      libdeflate_alloc_decompressor());
  if (!decompressor) throw PngError("cannot allocate a deflate decompressor");
  return decompressor.get();
}

void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 24));
  out.push_back(static_cast<std::uint8_t>(v >> 16));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}

std::uint32_t get_u32(const std::uint8_t* p) {
  return (static_cast<std::uint32_t>(p[0]) << 24) | (static_cast<std::uint32_t>(p[1]) << 16) |
         (static_cast<std::uint32_t>(p[2]) << 8) | p[3];
}

void put_chunk(std::vector<std::uint8_t>& out, const char* type, const std::uint8_t* data, std::size_t size) {
  put_u32(out, static_cast<std::uint32_t>(size));
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data, data + size);
  put_u32(out, libdeflate_crc32(0, out.data() + start, size + 4));
}

// A buffer of `size` bytes kept by the thread from one image to the next, its contents unspecified:
// a tile's filtered rows and deflated stream are larger than malloc's mmap threshold, and fresh
// buffers cost a zero fill and a page fault per 4 KB, a quarter of a tile's encoding.
std::span<std::uint8_t> reused_buffer(std::vector<std::uint8_t>& buffer, std::size_t size) {
  if (buffer.size() < size) buffer.resize(size);
  return {buffer.data(), size};
}

thread_local std::vector<std::uint8_t> png_filtered, png_deflated;

// `filtered` holds height rows of (filter byte + stride bytes).
std::vector<std::uint8_t> assemble(std::span<const std::uint8_t> filtered, int width, int height, int bit_depth,
                                   int color_type, int level) {
  libdeflate_compressor* compressor = thread_compressor(level);
  const std::span<std::uint8_t> idat =
      reused_buffer(png_deflated, libdeflate_zlib_compress_bound(compressor, filtered.size()));
  const std::size_t n =
      libdeflate_zlib_compress(compressor, filtered.data(), filtered.size(), idat.data(), idat.size());
  if (n == 0) throw PngError("deflate failed");
  std::vector<std::uint8_t> out(std::begin(kSignature), std::end(kSignature));
  out.reserve(n + 64);
  std::uint8_t ihdr[13];
  for (int i = 0; i < 4; ++i) {
    ihdr[i] = static_cast<std::uint8_t>(static_cast<std::uint32_t>(width) >> (24 - 8 * i));
    ihdr[4 + i] = static_cast<std::uint8_t>(static_cast<std::uint32_t>(height) >> (24 - 8 * i));
  }
  ihdr[8] = static_cast<std::uint8_t>(bit_depth);
  ihdr[9] = static_cast<std::uint8_t>(color_type);
  ihdr[10] = ihdr[11] = ihdr[12] = 0;  // deflate, adaptive filtering, no interlace
  put_chunk(out, "IHDR", ihdr, sizeof ihdr);
  put_chunk(out, "IDAT", idat.data(), n);
  put_chunk(out, "IEND", nullptr, 0);
  return out;
}

std::uint8_t paeth(std::uint8_t a, std::uint8_t b, std::uint8_t c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

// Undoes the five PNG filters in place; false on an unknown filter type.
bool unfilter(std::uint8_t* data, std::size_t stride, int height, int bpp) {
  std::uint8_t* previous = nullptr;
  for (int r = 0; r < height; ++r) {
    std::uint8_t* row = data + static_cast<std::size_t>(r) * (stride + 1);
    const std::uint8_t type = row[0];
    std::uint8_t* x = row + 1;
    const std::uint8_t* up = previous;
    const auto b = static_cast<std::size_t>(bpp);
    switch (type) {
      case 0:
        break;
      case 1:
        for (std::size_t i = b; i < stride; ++i) x[i] = static_cast<std::uint8_t>(x[i] + x[i - b]);
        break;
      case 2:
        if (up) {
          for (std::size_t i = 0; i < stride; ++i) x[i] = static_cast<std::uint8_t>(x[i] + up[i]);
        }
        break;
      case 3:
        for (std::size_t i = 0; i < stride; ++i) {
          const int left = i >= b ? x[i - b] : 0, above = up ? up[i] : 0;
          x[i] = static_cast<std::uint8_t>(x[i] + ((left + above) >> 1));
        }
        break;
      case 4:
        for (std::size_t i = 0; i < stride; ++i) {
          const std::uint8_t left = i >= b ? x[i - b] : 0, above = up ? up[i] : 0,
                             corner = (up && i >= b) ? up[i - b] : 0;
          x[i] = static_cast<std::uint8_t>(x[i] + paeth(left, above, corner));
        }
        break;
      default:
        return false;
    }
    previous = x;
  }
  return true;
}

// IHDR's fields into `image`; false for a format the fast path leaves to libpng (interlaced,
// palette, grey + alpha, other depths). Throws for a corrupt header or one past `max_side`.
bool read_header(const std::uint8_t* data, std::uint32_t size, const std::string& what, int max_side, PngImage& image) {
  if (size != 13) throw PngError(what + ": corrupt PNG: bad IHDR");
  image.width = static_cast<int>(get_u32(data));
  image.height = static_cast<int>(get_u32(data + 4));
  image.bit_depth = data[8];
  const int color = data[9];
  if (data[10] != 0 || data[11] != 0 || data[12] != 0) return false;  // interlaced: libpng
  if (image.bit_depth == 8 && (color == 0 || color == 2 || color == 6)) {
    image.channels = color == 0 ? 1 : (color == 2 ? 3 : 4);
  } else if (image.bit_depth == 16 && color == 0) {
    image.channels = 1;
  } else {
    return false;
  }
  // Before anything is allocated: a corrupt or hostile header cannot ask for gigabytes.
  if (image.width <= 0 || image.height <= 0 || image.width > max_side || image.height > max_side) {
    throw PngError(what + ": image of " + std::to_string(get_u32(data)) + " x " + std::to_string(get_u32(data + 4)) +
                   " pixels; the largest accepted side is " + std::to_string(max_side));
  }
  return true;
}

// A PNG's header and its zlib stream: read in place when it is one IDAT chunk (as we write it),
// else gathered into a thread-local buffer.
struct PngChunks {
  PngImage image;  ///< the header's fields, no pixels yet
  std::span<const std::uint8_t> zdata;
};

// The chunks the fast path handles; nullopt for anything else (libpng decides then). Throws for a
// corrupt file.
std::optional<PngChunks> read_chunks(std::span<const std::uint8_t> blob, const std::string& what, int max_side) {
  std::size_t offset = 8;
  PngChunks chunks;
  thread_local std::vector<std::uint8_t> gathered;
  gathered.clear();
  int idat_chunks = 0;
  bool have_header = false, ended = false;
  while (offset + 12 <= blob.size()) {
    const std::uint32_t size = get_u32(blob.data() + offset);
    if (size > blob.size() - offset - 12) throw PngError(what + ": corrupt PNG: chunk runs past the end");
    const std::uint8_t* type = blob.data() + offset + 4;
    const std::uint8_t* data = type + 4;
    if (libdeflate_crc32(0, type, size + 4) != get_u32(data + size)) {
      throw PngError(what + ": corrupt PNG: CRC error in a " + std::string(reinterpret_cast<const char*>(type), 4) +
                     " chunk");
    }
    if (std::memcmp(type, "IHDR", 4) == 0) {
      if (have_header) throw PngError(what + ": corrupt PNG: bad IHDR");
      if (!read_header(data, size, what, max_side, chunks.image)) return std::nullopt;
      have_header = true;
    } else if (!have_header) {
      throw PngError(what + ": corrupt PNG: the first chunk is not IHDR");
    } else if (std::memcmp(type, "IDAT", 4) == 0) {
      if (++idat_chunks == 1) {
        chunks.zdata = {data, size};
      } else {
        if (idat_chunks == 2) gathered.assign(chunks.zdata.begin(), chunks.zdata.end());
        gathered.insert(gathered.end(), data, data + size);
        chunks.zdata = gathered;
      }
    } else if (std::memcmp(type, "IEND", 4) == 0) {
      ended = true;
      break;
    } else if ((type[0] & 0x20) == 0) {
      return std::nullopt;  // another critical chunk (PLTE ...): libpng
    }
    offset += size + 12;
  }
  if (!have_header || !ended) throw PngError(what + ": corrupt PNG: truncated");
  return chunks;
}

// 16-bit grey rows (`raw`: each row's filter byte, then its samples) into image.pixels16: rows
// filtered with "sub" (ours) are unfiltered and byte-swapped in one pass on whole samples; other
// filters go through the generic unfilter first.
void unpack_grey16(std::vector<std::uint8_t>& raw, std::size_t stride, const std::string& what, PngImage& image) {
  bool all_sub = true;
  for (int r = 0; r < image.height && all_sub; ++r) all_sub = raw[static_cast<std::size_t>(r) * (stride + 1)] == 1;
  if (!all_sub && !unfilter(raw.data(), stride, image.height, 2)) {
    throw PngError(what + ": corrupt PNG: unknown filter type");
  }
  image.pixels16.resize(static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height));
  for (int r = 0; r < image.height; ++r) {
    const std::uint8_t* src = raw.data() + static_cast<std::size_t>(r) * (stride + 1) + 1;
    std::uint16_t* dst = image.pixels16.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(image.width);
    if (all_sub) {
      // Byte-wise sub with bpp 2 adds the high and the low bytes separately, modulo 256.
      std::uint8_t hi = 0, lo = 0;
      for (int i = 0; i < image.width; ++i, src += 2) {
        hi = static_cast<std::uint8_t>(hi + src[0]);
        lo = static_cast<std::uint8_t>(lo + src[1]);
        dst[i] = static_cast<std::uint16_t>((hi << 8) | lo);
      }
    } else {
      for (int i = 0; i < image.width; ++i, src += 2) dst[i] = static_cast<std::uint16_t>((src[0] << 8) | src[1]);
    }
  }
}

// Decodes the PNGs the fast path handles; nullopt for anything else (libpng decides then).
std::optional<PngImage> decode_fast(std::span<const std::uint8_t> blob, const std::string& what, int max_side) {
  if (blob.size() < 8 + 25 || std::memcmp(blob.data(), kSignature, 8) != 0) return std::nullopt;
  auto chunks = read_chunks(blob, what, max_side);
  if (!chunks) return std::nullopt;
  PngImage& image = chunks->image;
  const int bpp = image.channels * image.bit_depth / 8;
  const std::size_t stride = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(bpp);
  thread_local std::vector<std::uint8_t> raw;  // reused: no page faults on every tile
  raw.resize((stride + 1) * static_cast<std::size_t>(image.height));
  std::size_t produced = 0;
  const auto rc = libdeflate_zlib_decompress(thread_decompressor(), chunks->zdata.data(), chunks->zdata.size(),
                                             raw.data(), raw.size(), &produced);
  if (rc != LIBDEFLATE_SUCCESS || produced != raw.size()) throw PngError(what + ": corrupt PNG: bad image data");
  if (image.bit_depth == 16) {
    unpack_grey16(raw, stride, what, image);
    return std::move(image);
  }
  if (!unfilter(raw.data(), stride, image.height, bpp)) throw PngError(what + ": corrupt PNG: unknown filter type");
  image.pixels8.resize(stride * static_cast<std::size_t>(image.height));
  for (int r = 0; r < image.height; ++r) {
    std::memcpy(image.pixels8.data() + static_cast<std::size_t>(r) * stride,
                raw.data() + static_cast<std::size_t>(r) * (stride + 1) + 1, stride);
  }
  return std::move(image);
}

}  // namespace

namespace {

// Filter "none": class rasters and observations are runs of equal bytes, which deflate directly.
std::vector<std::uint8_t> encode_png8(std::span<const std::uint8_t> pixels, int width, int height, int channels,
                                      const char* what) {
  if (width <= 0 || height <= 0 ||
      pixels.size() !=
          static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * static_cast<std::size_t>(channels)) {
    throw PngError(std::string(what) + ": buffer size does not match the image size");
  }
  const std::size_t stride = static_cast<std::size_t>(width) * static_cast<std::size_t>(channels);
  const std::span<std::uint8_t> filtered = reused_buffer(png_filtered, (stride + 1) * static_cast<std::size_t>(height));
  for (int r = 0; r < height; ++r) {
    std::uint8_t* row = filtered.data() + static_cast<std::size_t>(r) * (stride + 1);
    row[0] = 0;
    std::memcpy(row + 1, pixels.data() + static_cast<std::size_t>(r) * stride, stride);
  }
  return assemble(filtered, width, height, 8, channels == 4 ? 0x6 : 0x2, 2);
}

}  // namespace

std::vector<std::uint8_t> encode_png_rgb8(std::span<const std::uint8_t> rgb, int width, int height) {
  return encode_png8(rgb, width, height, 3, "encode_png_rgb8");
}

std::vector<std::uint8_t> encode_png_rgba8(std::span<const std::uint8_t> rgba, int width, int height) {
  return encode_png8(rgba, width, height, 4, "encode_png_rgba8");
}

std::vector<std::uint8_t> encode_png_gray16(std::span<const std::uint16_t> values, int width, int height) {
  if (values.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height)) {
    throw PngError("encode_png_gray16: buffer size does not match the image size");
  }
  // Filter "sub" on the big-endian samples: the smooth distance ramps become small residuals.
  const std::size_t stride = static_cast<std::size_t>(width) * 2;
  const std::span<std::uint8_t> filtered = reused_buffer(png_filtered, (stride + 1) * static_cast<std::size_t>(height));
  for (int r = 0; r < height; ++r) {
    std::uint8_t* row = filtered.data() + static_cast<std::size_t>(r) * (stride + 1);
    const std::uint16_t* v = values.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(width);
    row[0] = 1;
    std::uint8_t previous_hi = 0, previous_lo = 0;
    for (int i = 0; i < width; ++i) {
      const auto hi = static_cast<std::uint8_t>(v[i] >> 8), lo = static_cast<std::uint8_t>(v[i]);
      row[1 + 2 * i] = static_cast<std::uint8_t>(hi - previous_hi);
      row[2 + 2 * i] = static_cast<std::uint8_t>(lo - previous_lo);
      previous_hi = hi;
      previous_lo = lo;
    }
  }
  return assemble(filtered, width, height, 16, 0x0, 1);
}

PngImage decode_png(std::span<const std::uint8_t> blob, const std::string& what, int max_side) {
  if (blob.size() < 8 || png_sig_cmp(blob.data(), 0, 8) != 0) throw PngError(what + ": not a PNG image");
  if (auto image = decode_fast(blob, what, max_side)) return std::move(*image);
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
  if (width == 0 || height == 0 || width > static_cast<png_uint_32>(max_side) ||
      height > static_cast<png_uint_32>(max_side)) {
    png_error(png, "image larger than the largest accepted side");
  }
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
