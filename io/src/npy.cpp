#include "seqloc/io/npy.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cstring>
#include <optional>
#include <utility>
#include <vector>

namespace seqloc::io {
namespace {

// The header is a Python dict literal, e.g. {'descr': '<f4', 'fortran_order': False,
// 'shape': (128, 128, 256), }. This parser accepts exactly the values NumPy writes.
struct Header {
  std::string descr;
  std::optional<bool> fortran_order;
  std::optional<std::vector<std::uint64_t>> shape;
};

class HeaderParser {
 public:
  HeaderParser(const std::string& text, std::string file) : s_(text), file_(std::move(file)) {}

  Header parse() {
    Header h;
    expect('{');
    while (true) {
      skip_space();
      if (peek() == '}') break;
      const std::string key = string_literal();
      expect(':');
      skip_space();
      if (key == "descr") {
        h.descr = string_literal();
      } else if (key == "fortran_order") {
        h.fortran_order = boolean();
      } else if (key == "shape") {
        h.shape = tuple();
      } else {
        fail("unknown header key '" + key + "'");
      }
      skip_space();
      if (peek() == ',') {
        ++i_;
        continue;
      }
      skip_space();
      if (peek() != '}') fail("expected ',' or '}' in the header");
    }
    return h;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw DataError(file_ + ": not a valid .npy header: " + what);
  }
  char peek() const { return i_ < s_.size() ? s_[i_] : '\0'; }
  void skip_space() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  void expect(char c) {
    skip_space();
    if (peek() != c) fail(std::string("expected '") + c + "'");
    ++i_;
  }
  std::string string_literal() {
    skip_space();
    const char quote = peek();
    if (quote != '\'' && quote != '"') fail("expected a string");
    ++i_;
    const auto end = s_.find(quote, i_);
    if (end == std::string::npos) fail("unterminated string");
    std::string out = s_.substr(i_, end - i_);
    i_ = end + 1;
    return out;
  }
  bool boolean() {
    if (s_.compare(i_, 4, "True") == 0) {
      i_ += 4;
      return true;
    }
    if (s_.compare(i_, 5, "False") == 0) {
      i_ += 5;
      return false;
    }
    fail("expected True or False");
  }
  std::vector<std::uint64_t> tuple() {
    expect('(');
    std::vector<std::uint64_t> out;
    while (true) {
      skip_space();
      if (peek() == ')') {
        ++i_;
        return out;
      }
      if (!std::isdigit(static_cast<unsigned char>(peek()))) fail("expected a dimension in the shape");
      std::uint64_t value = 0;
      while (std::isdigit(static_cast<unsigned char>(peek()))) {
        if (value > (1ull << 40)) fail("absurd dimension in the shape");
        value = value * 10 + static_cast<std::uint64_t>(peek() - '0');
        ++i_;
      }
      out.push_back(value);
      skip_space();
      if (peek() == ',') ++i_;
    }
  }

  const std::string& s_;
  std::string file_;
  std::size_t i_ = 0;
};

}  // namespace

namespace {

// A file descriptor closed on every way out.
struct FileDescriptor {
  int fd;
  explicit FileDescriptor(int f) : fd(f) {}
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  ~FileDescriptor() {
    if (fd >= 0) ::close(fd);
  }
};

// Where the header text lies: after the magic, the version and the header's length.
struct HeaderSpan {
  std::uint64_t start = 0, length = 0;
};

HeaderSpan read_preamble(int fd, std::uint64_t file_bytes, const std::string& name) {
  auto fail = [&](const std::string& what) { throw DataError(name + ": " + what); };
  unsigned char pre[12] = {};
  const ssize_t got = ::pread(fd, pre, sizeof pre, 0);
  if (got < 10 || std::memcmp(pre, "\x93NUMPY", 6) != 0) fail(file_bytes == 0 ? "empty file" : "not a .npy file");
  const int major = pre[6];
  HeaderSpan span;
  if (major == 1) {
    span.length = static_cast<std::uint64_t>(pre[8]) | (static_cast<std::uint64_t>(pre[9]) << 8);
    span.start = 10;
  } else if (major == 2 || major == 3) {
    if (got < 12) fail("truncated .npy preamble");
    span.length = static_cast<std::uint64_t>(pre[8]) | (static_cast<std::uint64_t>(pre[9]) << 8) |
                  (static_cast<std::uint64_t>(pre[10]) << 16) | (static_cast<std::uint64_t>(pre[11]) << 24);
    span.start = 12;
  } else {
    fail(".npy format version " + std::to_string(major) + " is not supported (1, 2 or 3)");
  }
  if (span.length > (1u << 20) || span.start + span.length > file_bytes) fail("truncated .npy header");
  return span;
}

// The header's dtype as a volume type and its item size; its shape checked as (H, W, N) within
// kMaxVolumeCells.
std::pair<core::VolumeType, std::size_t> check_header(const Header& h, const std::string& name) {
  auto fail = [&](const std::string& what) { throw DataError(name + ": " + what); };
  std::pair<core::VolumeType, std::size_t> type{core::VolumeType::float32, 4};
  if (h.descr == "<f2") {
    type = {core::VolumeType::float16, 2};
  } else if (h.descr != "<f4") {
    fail("dtype '" + h.descr + "' is not supported; volumes are little-endian float32 ('<f4') or float16 ('<f2')");
  }
  if (!h.fortran_order || !h.shape) fail("the header lacks 'fortran_order' or 'shape'");
  if (*h.fortran_order) fail("Fortran order is not supported; save a C-ordered array (np.ascontiguousarray)");
  const auto& shape = *h.shape;
  if (shape.size() != 3) {
    std::string dims;
    for (auto d : shape) dims += (dims.empty() ? "" : ", ") + std::to_string(d);
    fail("shape (" + dims + ") is not (H, W, N)");
  }
  if (shape[0] == 0 || shape[1] == 0 || shape[2] == 0) fail("a dimension of the shape is zero");
  // Bounded one factor at a time, so that the product cannot overflow.
  const bool too_large = shape[0] > kMaxVolumeCells || shape[1] > kMaxVolumeCells || shape[2] > kMaxVolumeCells ||
                         shape[0] * shape[1] > kMaxVolumeCells || shape[0] * shape[1] * shape[2] > kMaxVolumeCells;
  if (too_large) {
    fail("shape (" + std::to_string(shape[0]) + ", " + std::to_string(shape[1]) + ", " + std::to_string(shape[2]) +
         ") exceeds the limit of " + std::to_string(kMaxVolumeCells) + " cells");
  }
  return type;
}

}  // namespace

NpyArray::NpyArray(const std::filesystem::path& path) : path_(path) {
  const std::string name = path.string();
  const FileDescriptor file(::open(name.c_str(), O_RDONLY | O_CLOEXEC));
  if (file.fd < 0) throw DataError(name + ": cannot open (" + std::strerror(errno) + ")");
  struct stat st {};
  if (::fstat(file.fd, &st) != 0 || !S_ISREG(st.st_mode)) throw DataError(name + ": not a regular file");
  const auto file_bytes = static_cast<std::uint64_t>(st.st_size);
  const HeaderSpan span = read_preamble(file.fd, file_bytes, name);
  std::string text(span.length, '\0');
  if (::pread(file.fd, text.data(), span.length, static_cast<off_t>(span.start)) != static_cast<ssize_t>(span.length)) {
    throw DataError(name + ": cannot read the .npy header");
  }
  const Header h = HeaderParser(text, name).parse();
  const auto [type, item] = check_header(h, name);
  type_ = type;
  const auto& shape = *h.shape;
  const std::uint64_t cells = shape[0] * shape[1] * shape[2];
  const std::uint64_t data_start = span.start + span.length;
  const std::uint64_t expected = cells * item;
  if (file_bytes - data_start != expected) {
    throw DataError(name + ": the header's shape needs " + std::to_string(expected) +
                    " bytes of data but the file holds " + std::to_string(file_bytes - data_start) +
                    (file_bytes - data_start < expected ? " (truncated)" : ""));
  }
  for (std::size_t i = 0; i < 3; ++i) shape_[i] = static_cast<int>(shape[i]);
  mapping_bytes_ = static_cast<std::size_t>(file_bytes);
  mapping_ = ::mmap(nullptr, mapping_bytes_, PROT_READ, MAP_PRIVATE, file.fd, 0);
  if (mapping_ == MAP_FAILED) {
    mapping_ = nullptr;
    throw DataError(name + ": cannot map the file (" + std::strerror(errno) + ")");
  }
  data_ = static_cast<const unsigned char*>(mapping_) + data_start;
  if (reinterpret_cast<std::uintptr_t>(data_) % item != 0) {
    release();
    throw DataError(name + ": data is not aligned to its dtype (header length " + std::to_string(span.length) + ")");
  }
}

void NpyArray::release() {
  if (mapping_) ::munmap(mapping_, mapping_bytes_);
  mapping_ = nullptr;
  data_ = nullptr;
}

NpyArray::~NpyArray() { release(); }

NpyArray::NpyArray(NpyArray&& o) noexcept
    : path_(std::move(o.path_)),
      mapping_(o.mapping_),
      mapping_bytes_(o.mapping_bytes_),
      data_(o.data_),
      shape_(o.shape_),
      type_(o.type_) {
  o.mapping_ = nullptr;
  o.data_ = nullptr;
}

NpyArray& NpyArray::operator=(NpyArray&& o) noexcept {
  if (this != &o) {
    release();
    path_ = std::move(o.path_);
    mapping_ = o.mapping_;
    mapping_bytes_ = o.mapping_bytes_;
    data_ = o.data_;
    shape_ = o.shape_;
    type_ = o.type_;
    o.mapping_ = nullptr;
    o.data_ = nullptr;
  }
  return *this;
}

namespace {

// A C-order array of shape (d0, d1, d2) of `element`-byte values of NumPy type `descr`.
std::string encode_npy(const char* descr, std::size_t element, int d0, int d1, int d2, const void* data) {
  std::string header = std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (" +
                       std::to_string(d0) + ", " + std::to_string(d1) + ", " + std::to_string(d2) + "), }";
  // Magic (6), version (2), header length (2) and the header padded with spaces to a multiple of
  // 64 bytes, ended by a newline.
  header.append((64 - (10 + header.size() + 1) % 64) % 64, ' ');
  header.push_back('\n');
  std::string out("\x93NUMPY\x01\x00", 8);
  out.push_back(static_cast<char>(header.size() & 0xff));
  out.push_back(static_cast<char>(header.size() >> 8));
  out += header;
  const std::size_t bytes =
      static_cast<std::size_t>(d0) * static_cast<std::size_t>(d1) * static_cast<std::size_t>(d2) * element;
  out.append(static_cast<const char*>(data), bytes);  // little-endian hosts only, as the reader
  return out;
}

}  // namespace

std::string encode_npy_float32(int d0, int d1, int d2, const float* data) {
  return encode_npy("<f4", 4, d0, d1, d2, data);
}

std::string encode_npy_float16(int d0, int d1, int d2, const std::uint16_t* halves) {
  return encode_npy("<f2", 2, d0, d1, d2, halves);
}

}  // namespace seqloc::io
