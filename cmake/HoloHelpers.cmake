# holo_add_library(NAME holo_x SRCS a.cc b.cc PUBLIC_LINK_LIBS ... PRIVATE_LINK_LIBS ...)
# One folder = one library = one namespace. Headers are included as "common/camera.h".
function(holo_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SRCS;PUBLIC_LINK_LIBS;PRIVATE_LINK_LIBS" ${ARGN})
  add_library(${ARG_NAME} STATIC ${ARG_SRCS})
  target_include_directories(${ARG_NAME} PUBLIC ${HOLO_SOURCE_DIR})
  target_link_libraries(${ARG_NAME} PUBLIC ${ARG_PUBLIC_LINK_LIBS} PRIVATE ${ARG_PRIVATE_LINK_LIBS})
  target_compile_definitions(${ARG_NAME} PUBLIC HOLO_SOURCE_DIR="${HOLO_SOURCE_DIR}")
endfunction()

# holo_add_executable(NAME prog SRCS main.cc LINK_LIBS ... [WIRING_SRCS x_main.cc])
# WIRING_SRCS are sources that only parse options and connect library parts
# (no per-frame work of their own): a Release build compiles them at -O1, as
# it does test sources. -O3 made server_main.cc 30 s of CPU, -O1 17 s, and
# the program mains are ~240 s of CPU of a Release build.
function(holo_add_executable)
  cmake_parse_arguments(ARG "" "NAME" "SRCS;LINK_LIBS;WIRING_SRCS" ${ARGN})
  add_executable(${ARG_NAME} ${ARG_SRCS} ${ARG_WIRING_SRCS})
  target_link_libraries(${ARG_NAME} PRIVATE ${ARG_LINK_LIBS})
  set_target_properties(${ARG_NAME} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/bin)
  if(ARG_WIRING_SRCS AND CMAKE_BUILD_TYPE STREQUAL "Release" AND NOT HOLO_SANITIZE)
    set_source_files_properties(${ARG_WIRING_SRCS} TARGET_DIRECTORY ${ARG_NAME} PROPERTIES COMPILE_OPTIONS -O1)
  endif()
endfunction()

# holo_add_test(NAME test_x SRCS x_test.cc LINK_LIBS ... LABELS unit;slow)
function(holo_add_test)
  cmake_parse_arguments(ARG "" "NAME" "SRCS;LINK_LIBS;LABELS" ${ARGN})
  add_executable(${ARG_NAME} ${ARG_SRCS})
  target_link_libraries(${ARG_NAME} PRIVATE ${ARG_LINK_LIBS} GTest::gtest_main)
  target_compile_definitions(${ARG_NAME} PRIVATE HOLO_TEST_DATA_DIR="${HOLO_SOURCE_DIR}/tests/data")
  set_target_properties(${ARG_NAME} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  # One CTest test per executable (gtest_discover_tests cannot carry several labels).
  add_test(NAME ${ARG_NAME} COMMAND ${ARG_NAME} --gtest_brief=1)
  set_tests_properties(${ARG_NAME} PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT 900)
endfunction()

# holo_unity(TARGET BATCH [SKIP file.cc ...]): compiles TARGET as unity
# sources of BATCH files each. Most of a source's compile time here is the
# headers (Eigen, spdlog, nlohmann::json, asio) and the code they emit, so
# files that share them compile in 40–60 % less CPU together. It asks that
# the names a file keeps to itself (its anonymous namespace) differ from
# its neighbours'; SKIP lists files that stay alone. -DHOLO_UNITY=OFF
# compiles every file alone (to check that each includes what it uses).
function(holo_unity target batch)
  cmake_parse_arguments(ARG "" "" "SKIP" ${ARGN})
  if(NOT HOLO_UNITY)
    return()
  endif()
  set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE ${batch})
  foreach(f ${ARG_SKIP})
    set_source_files_properties(${f} TARGET_DIRECTORY ${target} PROPERTIES SKIP_UNITY_BUILD_INCLUSION ON)
  endforeach()
  # A class that holds a file-local type (the pimpl pattern) is no longer in
  # "the main file" once included by the unity source: GCC would warn.
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    target_compile_options(${target} PRIVATE -Wno-subobject-linkage)
  endif()
endfunction()
