# Compiler settings shared by every seqloc target.
add_library(seqloc_compile_options INTERFACE)
# C++ only: nvcc (the CUDA backend's .cu files) takes its own flags.
target_compile_options(seqloc_compile_options INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow
                                                        -Wconversion -Wno-sign-conversion>)
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 13)
  # GCC 12 false positives inside libstdc++ and libosmium headers at -O2 (GCC bugs 105329 and
  # 105651: std::string concatenation "may overlap"; strlen "reading from a region of size 0").
  target_compile_options(seqloc_compile_options INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Wno-restrict -Wno-stringop-overread>)
endif()
# The filter's inner loops want AVX2 and FMA. Default: x86-64-v3 when the build machine has them
# (not -march=native: Valgrind cannot run AVX-512 code). Set SEQLOC_ARCH to "" for a portable build.
if(NOT DEFINED SEQLOC_ARCH)
  set(SEQLOC_ARCH "")
  if(EXISTS /proc/cpuinfo)
    file(READ /proc/cpuinfo cpuinfo)
    if(cpuinfo MATCHES " avx2 " AND cpuinfo MATCHES " fma " AND CMAKE_SYSTEM_PROCESSOR MATCHES "x86_64")
      set(SEQLOC_ARCH "x86-64-v3")
    endif()
  endif()
  set(SEQLOC_ARCH "${SEQLOC_ARCH}" CACHE STRING "Value of -march (empty: the compiler's default)")
endif()
if(SEQLOC_ARCH)
  target_compile_options(seqloc_compile_options INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-march=${SEQLOC_ARCH}>)
endif()
if(SEQLOC_WERROR)
  target_compile_options(seqloc_compile_options INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
endif()
if(SEQLOC_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "SEQLOC_FUZZ needs clang (libFuzzer): configure with CXX=clang++ (scripts/fuzz does)")
  endif()
  set(SEQLOC_SANITIZE ON)
  # Coverage instrumentation everywhere; the fuzz targets alone link libFuzzer's main.
  target_compile_options(seqloc_compile_options INTERFACE -fsanitize=fuzzer-no-link)
endif()
if(SEQLOC_SANITIZE)
  target_compile_options(seqloc_compile_options INTERFACE -fsanitize=address,undefined -fno-omit-frame-pointer
                                                          -fno-sanitize-recover=undefined)
  target_link_options(seqloc_compile_options INTERFACE -fsanitize=address,undefined)
endif()
if(SEQLOC_FUZZ)
  # Recoverable, so that fuzz/ubsan-suppressions.txt can name the one upstream defect (libosmium's
  # coordinate parser) that would otherwise stop every OSM fuzz run; unsuppressed ones still halt.
  target_compile_options(seqloc_compile_options INTERFACE -fsanitize-recover=signed-integer-overflow)
endif()

# seqloc_module(NAME SOURCES... [PUBLIC deps...] [PRIVATE deps...])
# Declares library seqloc_NAME with alias seqloc::NAME and public headers in NAME/include.
function(seqloc_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC;PRIVATE" ${ARGN})
  add_library(seqloc_${name} STATIC ${ARG_SOURCES})
  add_library(seqloc::${name} ALIAS seqloc_${name})
  target_include_directories(seqloc_${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include
                                            PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src)
  target_link_libraries(seqloc_${name} PUBLIC ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE} seqloc_compile_options)
  # Unity builds: files of a library compiled eight to a translation unit, so that the headers they
  # share (Eigen, libosmium, GDAL, the JSON library) are parsed and their inline functions compiled
  # once per batch; a third less build time, more under the sanitizers. A file that cannot share a
  # unit (GCC's -Wsubobject-linkage takes a class of one file holding a type from its anonymous
  # namespace for a header's) is marked SKIP_UNITY_BUILD_INCLUSION beside its library.
  set_target_properties(seqloc_${name} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE 8)
  # A public header compiles on its own: one translation unit per header checks it.
  file(GLOB_RECURSE headers CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/include/*.hpp)
  set(checks)
  foreach(header IN LISTS headers)
    file(RELATIVE_PATH rel ${CMAKE_CURRENT_SOURCE_DIR}/include ${header})
    string(MAKE_C_IDENTIFIER "${rel}" id)
    set(check ${CMAKE_CURRENT_BINARY_DIR}/header_checks/${id}.cpp)
    file(CONFIGURE OUTPUT ${check} CONTENT "#include <${rel}>\n")
    list(APPEND checks ${check})
  endforeach()
  # (Not again in the sanitizer build: whether a header compiles on its own does not change.)
  if(checks AND NOT SEQLOC_SANITIZE)
    add_library(seqloc_${name}_header_checks OBJECT ${checks})
    target_link_libraries(seqloc_${name}_header_checks PRIVATE seqloc_${name} seqloc_compile_options)
  endif()
endfunction()
