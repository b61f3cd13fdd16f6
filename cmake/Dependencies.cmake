# Every third-party dependency is found here, once (Debian 12 packages only;
# scripts/setup.sh installs them).

find_package(Eigen3 3.4 REQUIRED NO_MODULE)

# orocos KDL's config sets only orocos_kdl_LIBRARIES: wrap it in a target.
find_package(orocos_kdl REQUIRED)
add_library(foresight_kdl INTERFACE)
target_link_libraries(foresight_kdl INTERFACE ${orocos_kdl_LIBRARIES} Eigen3::Eigen)
target_include_directories(foresight_kdl SYSTEM INTERFACE ${orocos_kdl_INCLUDE_DIRS})

find_package(urdfdom REQUIRED)
find_package(yaml-cpp REQUIRED)
find_package(spdlog REQUIRED)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json REQUIRED)
find_package(Threads REQUIRED)
find_package(OpenSSL REQUIRED)  # SHA-256 trajectory content hash
find_package(GTest REQUIRED)
find_package(benchmark REQUIRED)

# idlc (cyclonedds-tools) must be on PATH at configure time.
find_package(CycloneDDS REQUIRED)

find_package(OpenCV 4.6 REQUIRED COMPONENTS core imgproc imgcodecs calib3d videoio)

find_package(PkgConfig REQUIRED)
pkg_check_modules(MODBUS REQUIRED IMPORTED_TARGET libmodbus)
pkg_check_modules(OSMESA REQUIRED IMPORTED_TARGET osmesa)
pkg_check_modules(EGL REQUIRED IMPORTED_TARGET egl)

# foresight_test_only(TARGET...): a program only tests run (a protocol peer,
# a stand-in daemon): out of `all` when FORESIGHT_BUILD_TESTS is OFF.
function(foresight_test_only)
  if(NOT FORESIGHT_BUILD_TESTS)
    set_target_properties(${ARGN} PROPERTIES EXCLUDE_FROM_ALL ON)
  endif()
endfunction()

# foresight_add_test(NAME SOURCES... LIBS ...): one gtest executable, its tests
# discovered into ctest. Tests see FORESIGHT_CONFIG_DIR and FORESIGHT_BIN_DIR.
# With FORESIGHT_BUILD_TESTS=OFF the executable stays out of `all` and ctest.
function(foresight_add_test name)
  cmake_parse_arguments(T "SERIAL" "TIMEOUT;LOCK" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  foresight_test_only(${name})
  target_link_libraries(${name} PRIVATE ${T_LIBS} GTest::gtest GTest::gmock GTest::gtest_main)
  # Shared test helpers (foresight/test/cli.hpp: run the CLI, scratch files).
  target_include_directories(${name} PRIVATE ${CMAKE_SOURCE_DIR}/common/test/support)
  target_compile_definitions(${name} PRIVATE
    FORESIGHT_CONFIG_DIR="${CMAKE_SOURCE_DIR}/config"
    FORESIGHT_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
    FORESIGHT_BIN_DIR="${CMAKE_BINARY_DIR}/bin")
  if(NOT FORESIGHT_BUILD_TESTS)
    return()
  endif()
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 300)
  endif()
  # LOCK: tests holding the same lock never run at the same time (e.g. the
  # ones that each start a real-time daemon: two FIFO loops on 2 cores would
  # stretch each other's motions).
  set(T_PROPERTIES TIMEOUT ${T_TIMEOUT})
  if(T_LABELS)
    list(APPEND T_PROPERTIES LABELS "${T_LABELS}")
  endif()
  if(T_LOCK)
    # ... and they start first (ctest -j runs higher COST first): the tests
    # holding a lock run one after another, so they are the run's critical
    # path, and the other tests fill the second core beside them instead of
    # leaving the locked ones to run alone at the end (measured: 623 s of the
    # run's 702 s were locked tests; a fresh build has no cost data of its own).
    list(APPEND T_PROPERTIES RESOURCE_LOCK ${T_LOCK} COST 1000)
  endif()
  # SERIAL: nothing else runs beside these tests (they measure a few
  # milliseconds of bus timing: production TPDO miss limits, heartbeat
  # consumer times, and a neighbour test on 2 cores shifts those).
  if(T_SERIAL)
    list(APPEND T_PROPERTIES RUN_SERIAL TRUE)
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES ${T_PROPERTIES})
endfunction()

# foresight_add_benchmark(NAME SOURCES... LIBS ...): bench/bench_<area>.
function(foresight_add_benchmark name)
  cmake_parse_arguments(B "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${B_SOURCES})
  target_link_libraries(${name} PRIVATE ${B_LIBS} benchmark::benchmark)
  target_compile_definitions(${name} PRIVATE
    FORESIGHT_CONFIG_DIR="${CMAKE_SOURCE_DIR}/config")
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/bench)
endfunction()
