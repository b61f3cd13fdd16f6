# Sanitizer builds (docs: scripts/sanitize.sh). One option, off by default:
#
#   -DFORESIGHT_SANITIZE=address,undefined   ASan + UBSan (+ float-cast-overflow,
#                                            which -fsanitize=undefined leaves out:
#                                            double-to-int overflows are behind
#                                            several bad-input cases of issue 13)
#   -DFORESIGHT_SANITIZE=thread              TSan
#
# Use a build directory of its own (build-asan, build-tsan), never build/.
# UBSan findings abort the test (-fno-sanitize-recover) so ctest sees them.
# Runtime options and the suppression files are set by scripts/sanitize.sh
# (ASAN_OPTIONS, UBSAN_OPTIONS, LSAN_OPTIONS=suppressions=cmake/sanitizers/lsan.supp).
# Works with GCC and Clang. Code may test FORESIGHT_SANITIZER (defined to 1 in
# every translation unit of a sanitizer build), e.g. the allocation counter of
# the no-allocation tests, which counts through the sanitizer's malloc hooks
# instead of replacing malloc (a replaced malloc crashes inside ASan's start-up).

set(FORESIGHT_SANITIZE "" CACHE STRING
    "Sanitizers to build with: empty (none), address,undefined or thread")

if(FORESIGHT_SANITIZE)
  string(REPLACE "," ";" _fs_list "${FORESIGHT_SANITIZE}")
  set(_fs_flags "")
  foreach(_s IN LISTS _fs_list)
    if(_s STREQUAL "address")
      list(APPEND _fs_flags -fsanitize=address)
    elseif(_s STREQUAL "undefined")
      list(APPEND _fs_flags -fsanitize=undefined -fsanitize=float-cast-overflow
           -fno-sanitize-recover=undefined,float-cast-overflow)
    elseif(_s STREQUAL "thread")
      list(APPEND _fs_flags -fsanitize=thread)
    else()
      message(FATAL_ERROR "FORESIGHT_SANITIZE: unknown sanitizer '${_s}' "
                          "(use address,undefined or thread)")
    endif()
  endforeach()
  if("thread" IN_LIST _fs_list AND "address" IN_LIST _fs_list)
    message(FATAL_ERROR "FORESIGHT_SANITIZE: thread and address cannot be combined")
  endif()
  list(APPEND _fs_flags -fno-omit-frame-pointer)
  add_compile_options(${_fs_flags})
  add_link_options(${_fs_flags})
  add_compile_definitions(FORESIGHT_SANITIZER=1)
  message(STATUS "Sanitizers: ${_fs_flags}")
endif()

# libFuzzer targets (fuzz/, scripts/fuzz.sh): Clang only. Every library is
# compiled with coverage instrumentation (-fsanitize=fuzzer-no-link) so the
# fuzzer sees the branches of the parsers it drives; the fuzz executables add
# -fsanitize=fuzzer (libFuzzer's main). Combine with
# FORESIGHT_SANITIZE=address,undefined.
option(FORESIGHT_FUZZ "Build the libFuzzer targets in fuzz/ (Clang)" OFF)
if(FORESIGHT_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "FORESIGHT_FUZZ needs Clang (libFuzzer): -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_C_COMPILER=clang")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
  add_link_options(-fsanitize=fuzzer-no-link)
endif()
