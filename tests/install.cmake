# install.cmake — registers the "install" test (included from
# tests/CMakeLists.txt): `cmake --install` into a scratch prefix, then
# examples/ built against it with find_package(hush) and with pkg-config,
# each run on a frame written by the installed `hush synth`.
add_test(NAME install COMMAND ${CMAKE_COMMAND}
  -DHUSH_BUILD_DIR=${PROJECT_BINARY_DIR}
  -DHUSH_SOURCE_DIR=${PROJECT_SOURCE_DIR}
  -DWORK_DIR=${CMAKE_CURRENT_BINARY_DIR}/install_test
  -DLIBDIR=${CMAKE_INSTALL_LIBDIR}
  -DBINDIR=${CMAKE_INSTALL_BINDIR}
  -DC_COMPILER=${CMAKE_C_COMPILER}
  "-DGENERATOR=${CMAKE_GENERATOR}"
  -DCONFIG=$<CONFIG>
  -DSANITIZE=${HUSH_SANITIZE}
  -P ${CMAKE_CURRENT_LIST_DIR}/test_install.cmake)
set_tests_properties(install PROPERTIES TIMEOUT 600 ENVIRONMENT "OMP_NUM_THREADS=2")
