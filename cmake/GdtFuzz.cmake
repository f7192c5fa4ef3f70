# GDT_FUZZ: the fuzzing build (tests/fuzz.cmake).  Every project library is
# compiled with libFuzzer's coverage instrumentation (fuzzer-no-link) and
# with AddressSanitizer + UndefinedBehaviorSanitizer, so the fuzz targets
# find memory errors and undefined behaviour anywhere below the readers;
# only the targets themselves link libFuzzer's main (-fsanitize=fuzzer).
# libFuzzer ships with clang only: another compiler is a configure error.
if(GDT_FUZZ)
  if(NOT CMAKE_C_COMPILER_ID STREQUAL "Clang" OR NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR
      "GDT_FUZZ=ON needs clang for C and C++ (found ${CMAKE_C_COMPILER_ID} / "
      "${CMAKE_CXX_COMPILER_ID}): configure a fresh build folder with "
      "-DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ (Debian packages "
      "'clang' and 'libclang-rt-14-dev', or run scripts/setup.sh)")
  endif()
  include(CheckCSourceCompiles)
  set(CMAKE_REQUIRED_FLAGS "-fsanitize=fuzzer")
  set(CMAKE_REQUIRED_LINK_OPTIONS "-fsanitize=fuzzer")
  check_c_source_compiles("
    #include <stddef.h>
    #include <stdint.h>
    int LLVMFuzzerTestOneInput(const uint8_t *d, size_t n);
    int LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) { (void)d; (void)n; return 0; }"
    GDT_HAVE_LIBFUZZER)
  unset(CMAKE_REQUIRED_FLAGS)
  unset(CMAKE_REQUIRED_LINK_OPTIONS)
  if(NOT GDT_HAVE_LIBFUZZER)
    message(FATAL_ERROR "GDT_FUZZ=ON: clang cannot link libFuzzer (-fsanitize=fuzzer): "
                        "install the Debian package 'libclang-rt-14-dev'")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endif()
