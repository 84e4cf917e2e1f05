# The CUDA backend (gpu/, docs/gpu.md): built where nvcc is found, which is every build machine of
# ours (CI's included, none of which has a GPU: the tests that need one skip themselves). Sets
# SEQLOC_CUDA. Not in the sanitizer build: nvcc's host code is not instrumented, and the host
# backend's tests already run in the plain build.
set(SEQLOC_CUDA OFF)
if(SEQLOC_WITH_CUDA AND NOT SEQLOC_SANITIZE)
  if(NOT DEFINED CMAKE_CUDA_COMPILER AND NOT DEFINED ENV{CUDACXX} AND EXISTS /usr/local/cuda/bin/nvcc)
    set(CMAKE_CUDA_COMPILER /usr/local/cuda/bin/nvcc)  # the toolkit's own place, when not on PATH
  endif()
  include(CheckLanguage)
  check_language(CUDA)
  if(CMAKE_CUDA_COMPILER)
    if(NOT DEFINED CMAKE_CUDA_ARCHITECTURES)
      set(CMAKE_CUDA_ARCHITECTURES 90)  # Hopper (H100, H200); set it for other cards
    endif()
    set(CMAKE_CUDA_HOST_COMPILER ${CMAKE_CXX_COMPILER})
    if(CMAKE_CXX_COMPILER_LAUNCHER AND NOT DEFINED CMAKE_CUDA_COMPILER_LAUNCHER)
      set(CMAKE_CUDA_COMPILER_LAUNCHER ${CMAKE_CXX_COMPILER_LAUNCHER})
    endif()
    # The runtime goes in by its imported target's full path (CUDA::cudart_static, gpu/): programs
    # that link the backend are linked by the C++ compiler, which does not know the toolkit's
    # library folder. No device linking.
    set(CMAKE_CUDA_RUNTIME_LIBRARY None)
    enable_language(CUDA)
    find_package(CUDAToolkit REQUIRED)
    # C++20 as the rest of seqloc. CMake 3.25 does not know nvcc 13's dialects: it is told the flag.
    if(NOT CMAKE_CUDA20_STANDARD_COMPILE_OPTION)
      set(CMAKE_CUDA20_STANDARD_COMPILE_OPTION "-std=c++20")
      set(CMAKE_CUDA20_EXTENSION_COMPILE_OPTION "-std=c++20")
    endif()
    set(CMAKE_CUDA_STANDARD 20)
    set(CMAKE_CUDA_STANDARD_REQUIRED ON)
    set(SEQLOC_CUDA ON)
    message(STATUS "CUDA backend: nvcc ${CMAKE_CUDA_COMPILER_VERSION}, architectures ${CMAKE_CUDA_ARCHITECTURES}")
  else()
    message(STATUS "CUDA backend: off (no nvcc found; --device cuda will say so)")
  endif()
endif()
set(SEQLOC_CUDA_FOUND ${SEQLOC_CUDA} CACHE INTERNAL "Whether the CUDA backend is built (scripts/gpu-check reads it)")
