# cmake -P script: install moreau from BUILD_DIR into WORK_DIR/prefix, then configure, build
# and run the consumer project in SOURCE_DIR against it with find_package(moreau <VERSION>),
# where VERSION is the source tree's VERSION file; the installed `moreau --version` and the
# Python package's moreau.__version__ (PYTHON with PYTHONPATH=PYTHON_PATH) must say the same.
file(REMOVE_RECURSE ${WORK_DIR})
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE code OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT code EQUAL 0)
    message(FATAL_ERROR "command failed (${code}): ${ARGN}\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()
file(STRINGS ${VERSION_FILE} version LIMIT_COUNT 1)
run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${WORK_DIR}/prefix)
if(NOT EXISTS ${WORK_DIR}/prefix/share/doc/moreau/LICENSE)
  message(FATAL_ERROR "the installed package lacks share/doc/moreau/LICENSE")
endif()
run(${WORK_DIR}/prefix/bin/moreau --version)
if(NOT run_output STREQUAL "moreau ${version}\n")
  message(FATAL_ERROR "`moreau --version` printed '${run_output}', VERSION says ${version}")
endif()
if(PYTHON)  # (no ';' in the code: CMake would split the argument there)
  run(${CMAKE_COMMAND} -E env PYTHONPATH=${PYTHON_PATH} ${PYTHON} -c
      "import importlib.metadata, moreau\nprint(moreau.__version__, importlib.metadata.version('moreau'))")
  if(NOT run_output STREQUAL "${version} ${version}\n")
    message(FATAL_ERROR "Python: moreau.__version__ and the package metadata say '${run_output}', "
      "VERSION says ${version}")
  endif()
endif()
set(flags "")
if(SANITIZE)  # a sanitized library needs a sanitized executable (runtime order)
  set(flags -DCMAKE_CXX_FLAGS=-fsanitize=address,undefined
            -DCMAKE_C_FLAGS=-fsanitize=address,undefined
            -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=address,undefined)
endif()
run(${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${WORK_DIR}/build -G ${GENERATOR}
    -DCMAKE_BUILD_TYPE=${BUILD_TYPE} -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix
    -DMOREAU_EXPECTED_VERSION=${version} ${flags})
run(${CMAKE_COMMAND} --build ${WORK_DIR}/build)
run(${WORK_DIR}/build/consumer)
run(${WORK_DIR}/build/c_consumer)
message(STATUS "consumer ran against the installed package, version ${version} everywhere")
