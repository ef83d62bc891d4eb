# Warning flags for moreau's own targets (never applied to dependencies).
function(moreau_target_options target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow=local -Wnon-virtual-dtor
    -Wold-style-cast -Wcast-align -Wunused -Woverloaded-virtual
    # GCC 12 reports false positives inside libstdc++'s std::string at -O3 (GCC bug 105329).
    -Wno-restrict)
  if(MOREAU_WARNINGS_AS_ERRORS)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()
