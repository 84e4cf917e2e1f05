// .npy volumes: files written by NumPy itself read back exactly; every malformed header, dtype,
// order, shape and size is one clear error naming the file.

#include <cstdio>
#include <fstream>

#include <gtest/gtest.h>

#include "seqloc/io/npy.hpp"
#include "support/test_support.hpp"

namespace seqloc::io {
namespace {

// Writes an .npy file by hand: magic, version 1.0, the header dict padded to 64 bytes, data.
void write_npy(const std::filesystem::path& path, const std::string& dict, const std::string& data, int major = 1) {
  std::string header = dict;
  const std::size_t preamble = major == 1 ? 10 : 12;
  while ((preamble + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::ofstream out(path, std::ios::binary);
  out << "\x93NUMPY" << static_cast<char>(major) << '\0';
  const auto n = static_cast<std::uint32_t>(header.size());
  out.put(static_cast<char>(n & 0xFF)).put(static_cast<char>((n >> 8) & 0xFF));
  if (major != 1) out.put(static_cast<char>((n >> 16) & 0xFF)).put(static_cast<char>(n >> 24));
  out << header << data;
}

std::string floats(std::initializer_list<float> values) {
  std::string s;
  for (float v : values) s.append(reinterpret_cast<const char*>(&v), 4);
  return s;
}

TEST(Npy, ReadsWhatNumPyWrites) {
  test::ScratchDir dir;
  const std::string script =
      "import numpy as np\n"
      "a = (np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4) - 7) / 4\n"
      "np.save('" +
      (dir / "f32.npy").string() +
      "', a)\n"
      "np.save('" +
      (dir / "f16.npy").string() +
      "', a.astype(np.float16))\n"
      "np.save('" +
      (dir / "big.npy").string() + "', np.zeros((64, 48, 256), np.float16))\n";
  std::ofstream(dir / "make.py") << script;
  const auto made = test::run_program("/usr/bin/python3", {(dir / "make.py").string()});
  ASSERT_EQ(made.exit_code, 0) << made.err;
  for (const char* name : {"f32.npy", "f16.npy"}) {
    const io::NpyVolume v(dir / name);
    EXPECT_EQ(v.height(), 2);
    EXPECT_EQ(v.width(), 3);
    EXPECT_EQ(v.bins(), 4);
    for (int i = 0; i < 24; ++i) {
      const float expected = static_cast<float>(i - 7) / 4;  // exact in float16 too
      const float got = v.type() == core::VolumeType::float32
                            ? static_cast<const float*>(v.data())[i]
                            : core::half_to_float(static_cast<const std::uint16_t*>(v.data())[i]);
      EXPECT_EQ(got, expected) << name << " cell " << i;
    }
  }
  const io::NpyVolume big(dir / "big.npy");
  EXPECT_EQ(big.bins(), 256);
  EXPECT_EQ(big.type(), core::VolumeType::float16);
  const auto view = big.view(core::VolumeValues::prob, 0.5);
  EXPECT_EQ(view.height, 64);
  EXPECT_EQ(view.values, core::VolumeValues::prob);
  io::NpyVolume moved = io::NpyVolume(dir / "f32.npy");
  EXPECT_EQ(moved.width(), 3);
}

TEST(Npy, VersionTwoHeaders) {
  test::ScratchDir dir;
  write_npy(dir / "v2.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 1, 2), }", floats({1.5f, -2.0f}), 2);
  const io::NpyVolume v(dir / "v2.npy");
  EXPECT_EQ(static_cast<const float*>(v.data())[1], -2.0f);
}

void expect_error(const std::filesystem::path& path, const std::string& fragment) {
  try {
    io::NpyVolume v(path);
    FAIL() << "no error for " << path << ", expected '" << fragment << "'";
  } catch (const DataError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    EXPECT_NE(message.find(fragment), std::string::npos) << message;
  }
}

TEST(Npy, BadFilesAreClearErrors) {
  test::ScratchDir dir;
  const std::string ok_dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2), }";
  const std::string data = floats({1, 2, 3, 4});
  expect_error(dir / "missing.npy", "cannot open");
  std::ofstream(dir / "empty.npy").close();
  expect_error(dir / "empty.npy", "empty file");
  std::ofstream(dir / "text.npy") << "just some text, long enough";
  expect_error(dir / "text.npy", "not a .npy file");
  write_npy(dir / "f8.npy", "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 2, 1), }", data);
  expect_error(dir / "f8.npy", "dtype '<f8' is not supported");
  write_npy(dir / "be.npy", "{'descr': '>f4', 'fortran_order': False, 'shape': (1, 2, 2), }", data);
  expect_error(dir / "be.npy", "dtype '>f4'");
  write_npy(dir / "fortran.npy", "{'descr': '<f4', 'fortran_order': True, 'shape': (1, 2, 2), }", data);
  expect_error(dir / "fortran.npy", "Fortran order");
  write_npy(dir / "2d.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2), }", data);
  expect_error(dir / "2d.npy", "shape (2, 2) is not (H, W, N)");
  write_npy(dir / "zero.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (0, 2, 2), }", "");
  expect_error(dir / "zero.npy", "zero");
  write_npy(dir / "short.npy", ok_dict, data.substr(0, 10));
  expect_error(dir / "short.npy", "(truncated)");
  write_npy(dir / "long.npy", ok_dict, data + "xxxx");
  expect_error(dir / "long.npy", "needs 16 bytes of data but the file holds 20");
  // A header claiming terabytes is refused from the header alone.
  write_npy(dir / "huge.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (1000000, 1000000, 1000000), }", data);
  expect_error(dir / "huge.npy", "exceeds the limit");
  write_npy(dir / "garbled.npy", "{'descr': '<f4', 'fortran_order': Maybe, 'shape': (1, 2, 2), }", data);
  expect_error(dir / "garbled.npy", "expected True or False");
  write_npy(dir / "nokey.npy", "{'descr': '<f4', 'shape': (1, 2, 2), }", data);
  expect_error(dir / "nokey.npy", "lacks 'fortran_order'");
  // The preamble promises more header than there is.
  std::ofstream(dir / "cut.npy", std::ios::binary) << std::string("\x93NUMPY\x01\x00\xff\x00{'descr'", 18);
  expect_error(dir / "cut.npy", "truncated .npy header");
}

}  // namespace
}  // namespace seqloc::io
