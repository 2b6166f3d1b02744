# test_install.cmake — the installed package works for a consumer (run by
# the "install" test, see install.cmake):
#   1. cmake --install BUILD --prefix WORK/prefix, and the expected files exist;
#   2. the installed `hush synth` writes a small sequence;
#   3. examples/ configured with CMAKE_PREFIX_PATH=prefix (find_package(hush),
#      hush::hush), built, and run on one of its frames;
#   4. examples/denoise_frame.c compiled with `cc $(pkg-config --cflags --libs
#      hush)` and PKG_CONFIG_PATH=prefix/lib/pkgconfig, run with
#      LD_LIBRARY_PATH=prefix/lib.
# Each run must exit 0 and write its EXR and PNG.
cmake_minimum_required(VERSION 3.18)

foreach(var HUSH_BUILD_DIR HUSH_SOURCE_DIR WORK_DIR LIBDIR BINDIR C_COMPILER)
  if(NOT DEFINED ${var} OR "${${var}}" STREQUAL "")
    message(FATAL_ERROR "test_install.cmake needs -D${var}=...")
  endif()
endforeach()
if(NOT GENERATOR)
  set(GENERATOR "Unix Makefiles")
endif()

set(prefix ${WORK_DIR}/prefix)
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})

# Runs a command; stops the test with its output if it fails. The output is
# left in run_output.
function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${ARGN}\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()

function(expect_file path)
  if(NOT EXISTS ${path})
    message(FATAL_ERROR "missing: ${path}")
  endif()
  file(SIZE ${path} size)
  if(size EQUAL 0)
    message(FATAL_ERROR "empty: ${path}")
  endif()
endfunction()

# A sanitized libhush needs a sanitized program to load it.
set(san_flags "")
if(SANITIZE)
  set(san_flags -fsanitize=address,undefined)
endif()

# 1. install
set(config_args "")
if(CONFIG)
  set(config_args --config ${CONFIG})
endif()
run("cmake --install" ${CMAKE_COMMAND} --install ${HUSH_BUILD_DIR} --prefix ${prefix} ${config_args})
foreach(f include/hush.h ${BINDIR}/hush ${LIBDIR}/pkgconfig/hush.pc
    ${LIBDIR}/cmake/hush/hushConfig.cmake ${LIBDIR}/cmake/hush/hushConfigVersion.cmake
    ${LIBDIR}/cmake/hush/hushTargets.cmake)
  expect_file(${prefix}/${f})
endforeach()
file(GLOB libs ${prefix}/${LIBDIR}/libhush.so*)
if(NOT libs)
  message(FATAL_ERROR "no libhush.so under ${prefix}/${LIBDIR}")
endif()

# 2. a frame from the installed command
run("hush synth" ${prefix}/${BINDIR}/hush synth --out ${WORK_DIR}/seq --size 64x48 --frames 2
  --quiet)
file(GLOB frames ${WORK_DIR}/seq/*.exr)
list(SORT frames)
list(GET frames 0 frame)

# 3. find_package(hush)
string(REPLACE ";" " " san_string "${san_flags}")
run("configure examples/" ${CMAKE_COMMAND} -S ${HUSH_SOURCE_DIR}/examples -B ${WORK_DIR}/build
  -G ${GENERATOR} -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_C_COMPILER=${C_COMPILER}
  -DCMAKE_BUILD_TYPE=Release "-DCMAKE_C_FLAGS=${san_string}"
  "-DCMAKE_EXE_LINKER_FLAGS=${san_string}")
run("build examples/" ${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run("denoise_frame (CMake)" ${WORK_DIR}/build/denoise_frame ${frame} ${WORK_DIR}/cmake.exr
  ${WORK_DIR}/cmake.png)
expect_file(${WORK_DIR}/cmake.exr)
expect_file(${WORK_DIR}/cmake.png)

# 4. pkg-config: hush.pc finds its prefix from its own place (relocatable),
#    so the flags must point under the scratch prefix without redefinition.
find_program(PKG_CONFIG pkg-config)
if(NOT PKG_CONFIG)
  message(FATAL_ERROR "pkg-config not found")
endif()
set(ENV{PKG_CONFIG_PATH} ${prefix}/${LIBDIR}/pkgconfig)
run("pkg-config" ${PKG_CONFIG} --cflags --libs hush)
string(STRIP "${run_output}" pc_flags)
# The paths may be spelled prefix/lib/pkgconfig/../../include: compare them
# resolved.
string(REGEX MATCH "-I([^ ]+)" _ "${pc_flags}")
get_filename_component(pc_include "${CMAKE_MATCH_1}" REALPATH)
string(REGEX MATCH "-L([^ ]+)" _ "${pc_flags}")
get_filename_component(pc_lib "${CMAKE_MATCH_1}" REALPATH)
get_filename_component(want_include "${prefix}/include" REALPATH)
get_filename_component(want_lib "${prefix}/${LIBDIR}" REALPATH)
if(NOT pc_include STREQUAL want_include OR NOT pc_lib STREQUAL want_lib)
  message(FATAL_ERROR "pkg-config gives '${pc_flags}', not the paths under ${prefix}")
endif()
separate_arguments(pc_list UNIX_COMMAND "${pc_flags}")
run("cc with pkg-config" ${C_COMPILER} ${HUSH_SOURCE_DIR}/examples/denoise_frame.c ${san_flags}
  ${pc_list} -o ${WORK_DIR}/denoise_frame_pc)
run("denoise_frame (pkg-config)" ${CMAKE_COMMAND} -E env
  LD_LIBRARY_PATH=${prefix}/${LIBDIR} ${WORK_DIR}/denoise_frame_pc ${frame}
  ${WORK_DIR}/pc.exr ${WORK_DIR}/pc.png)
expect_file(${WORK_DIR}/pc.exr)
expect_file(${WORK_DIR}/pc.png)
message(STATUS "installed hush: CMake package, pkg-config and the hush command all work")
