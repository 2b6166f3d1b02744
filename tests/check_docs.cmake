# Fails when docs/filters.md differs from what `hush filters --markdown` prints
# (regenerate with tools/gen-docs.sh).
execute_process(COMMAND ${HUSH} filters --markdown OUTPUT_VARIABLE tables RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "hush filters --markdown failed")
endif()
file(READ ${DOC} doc)
string(FIND "${doc}" "${tables}" at)
if(at EQUAL -1)
  message(FATAL_ERROR "docs/filters.md is stale: run tools/gen-docs.sh")
endif()
