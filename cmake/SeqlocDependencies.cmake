# Every dependency comes from a Debian package (see scripts/deps); nothing is downloaded.
find_package(Threads REQUIRED)
find_package(ZLIB REQUIRED)
find_package(BZip2 REQUIRED)
find_package(EXPAT REQUIRED)
find_package(PNG REQUIRED)
find_package(SQLite3 REQUIRED)
find_package(OpenSSL REQUIRED COMPONENTS Crypto)
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)

# libosmium and protozero are header-only; Debian ships no CMake config for them.
find_path(OSMIUM_INCLUDE_DIR osmium/osm.hpp REQUIRED)
find_path(PROTOZERO_INCLUDE_DIR protozero/pbf_reader.hpp REQUIRED)
add_library(seqloc_libosmium INTERFACE)
target_include_directories(seqloc_libosmium SYSTEM INTERFACE ${OSMIUM_INCLUDE_DIR} ${PROTOZERO_INCLUDE_DIR})
target_link_libraries(seqloc_libosmium INTERFACE ZLIB::ZLIB BZip2::BZip2 EXPAT::EXPAT Threads::Threads)
add_library(seqloc::libosmium ALIAS seqloc_libosmium)

# libdeflate (fast deflate/inflate for the PNG tiles) ships no CMake config.
find_path(LIBDEFLATE_INCLUDE_DIR libdeflate.h REQUIRED)
find_library(LIBDEFLATE_LIBRARY NAMES deflate REQUIRED)
add_library(seqloc_libdeflate INTERFACE)
target_include_directories(seqloc_libdeflate SYSTEM INTERFACE ${LIBDEFLATE_INCLUDE_DIR})
target_link_libraries(seqloc_libdeflate INTERFACE ${LIBDEFLATE_LIBRARY})
add_library(seqloc::libdeflate ALIAS seqloc_libdeflate)

# GeographicLib ships a Find module only.
find_path(GEOGRAPHICLIB_INCLUDE_DIR GeographicLib/TransverseMercator.hpp REQUIRED)
find_library(GEOGRAPHICLIB_LIBRARY NAMES GeographicLib Geographic REQUIRED)
add_library(seqloc_geographiclib INTERFACE)
target_include_directories(seqloc_geographiclib SYSTEM INTERFACE ${GEOGRAPHICLIB_INCLUDE_DIR})
target_link_libraries(seqloc_geographiclib INTERFACE ${GEOGRAPHICLIB_LIBRARY})
add_library(seqloc::geographiclib ALIAS seqloc_geographiclib)

# OpenCV: only core (the matcher's FFTs) and imgproc (blurs and the drawing of pictures). Their
# Debian -dev packages ship no CMake config (libopencv-dev, which does, pulls every module).
find_path(OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
find_library(OPENCV_CORE_LIBRARY NAMES opencv_core REQUIRED)
find_library(OPENCV_IMGPROC_LIBRARY NAMES opencv_imgproc REQUIRED)
add_library(seqloc_opencv INTERFACE)
target_include_directories(seqloc_opencv SYSTEM INTERFACE ${OPENCV_INCLUDE_DIR})
target_link_libraries(seqloc_opencv INTERFACE ${OPENCV_IMGPROC_LIBRARY} ${OPENCV_CORE_LIBRARY})
add_library(seqloc::opencv ALIAS seqloc_opencv)

# GDAL: GeoTIFF and COG output of the serve module (libgdal-dev ships a CMake config).
find_package(GDAL CONFIG REQUIRED)

# Boost.Beast and Asio (header-only, libboost-dev): the event-driven HTTP layer of `seqloc serve`.
find_package(Boost 1.74 CONFIG REQUIRED)
add_library(seqloc_beast INTERFACE)
target_link_libraries(seqloc_beast INTERFACE Boost::headers Threads::Threads)
target_compile_definitions(seqloc_beast INTERFACE BOOST_BEAST_USE_STD_STRING_VIEW BOOST_ASIO_NO_DEPRECATED)
add_library(seqloc::beast ALIAS seqloc_beast)

# cpp-httplib: the test suite's HTTP client. Debian builds it as a shared library; its
# pkg-config file carries the feature macros the library was compiled with, which every user
# must define alike (they change its ABI).
if(SEQLOC_BUILD_TESTS)
  find_package(PkgConfig REQUIRED)
  pkg_check_modules(HTTPLIB REQUIRED IMPORTED_TARGET cpp-httplib)
  add_library(seqloc_httplib INTERFACE)
  target_link_libraries(seqloc_httplib INTERFACE PkgConfig::HTTPLIB Threads::Threads)
  add_library(seqloc::httplib ALIAS seqloc_httplib)
endif()
