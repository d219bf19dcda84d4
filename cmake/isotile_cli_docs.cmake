# Generates the isotile man page and its bash completion from the CLI's own --help, at build time,
# so that neither holds a hand-maintained list of commands or options.
#
#   cmake -DISOTILE=<isotile> -DHELP2MAN=<help2man> -DOUT=<dir> -P isotile_cli_docs.cmake
#
# Writes OUT/isotile.1.gz (help2man over `isotile --help`, plus a COMMANDS section holding every
# subcommand's --help, and the EXIT STATUS, ENVIRONMENT, FILES and EXAMPLES sections of
# isotile.h2m beside this script) and OUT/isotile.bash (a bash completion: subcommands, their options, and
# the values of options restricted to a set, as CLI11 prints them: `--method TEXT:{mc,macet,dc}`).

function(run_help out)
  execute_process(COMMAND "${ISOTILE}" ${ARGN} --help OUTPUT_VARIABLE text RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "isotile ${ARGN} --help exited with ${rc}")
  endif()
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

# CLI11's help, one section at a time: the lines indented by two spaces under "NAME:" headers.
# Sets <prefix>_options (names, e.g. "-o;--output"), <prefix>_choices_<name> (a value set) and,
# for the top level, <prefix>_subcommands.
function(parse_help text prefix)
  # Unbalanced brackets ("in [0, 0.5)") would join CMake list elements: parsing needs none.
  string(REPLACE ";" "," text "${text}")
  string(REPLACE "[" "(" text "${text}")
  string(REPLACE "]" ")" text "${text}")
  string(REPLACE "\n" ";" lines "${text}")
  set(section "")
  set(options "")
  set(subcommands "")
  foreach(line IN LISTS lines)
    if(line MATCHES "^([A-Za-z]+):$")
      set(section "${CMAKE_MATCH_1}")
    elseif(section STREQUAL "Options" AND line MATCHES "^  (-[^ ]+)(  *[A-Z]+(:{([^}]*)})?)?")
      set(spec "${CMAKE_MATCH_4}")
      string(REPLACE "," ";" names "${CMAKE_MATCH_1}")
      list(APPEND options ${names})
      if(spec)
        string(REPLACE "," " " spec "${spec}")
        foreach(n IN LISTS names)
          set(${prefix}_choices_${n} "${spec}" PARENT_SCOPE)
        endforeach()
      endif()
    elseif(section STREQUAL "Subcommands" AND line MATCHES "^  ([a-z][a-z0-9-]*) ")
      list(APPEND subcommands "${CMAKE_MATCH_1}")
    endif()
  endforeach()
  set(${prefix}_options "${options}" PARENT_SCOPE)
  set(${prefix}_subcommands "${subcommands}" PARENT_SCOPE)
endfunction()

# Help text as preformatted roff: backslashes and minus signs escaped, no line read as a request.
function(to_roff text out)
  string(REPLACE "\\" "\\e" text "${text}")
  string(REPLACE "-" "\\-" text "${text}")
  string(REGEX REPLACE "(^|\n)([.'])" "\\1\\\\&\\2" text "${text}")
  set(${out} "${text}" PARENT_SCOPE)
endfunction()

file(MAKE_DIRECTORY "${OUT}")
run_help(top)
parse_help("${top}" top)
if(NOT top_subcommands)
  message(FATAL_ERROR "no subcommands found in `isotile --help`")
endif()

set(include "[COMMANDS]\nEach command has its own options; `isotile COMMAND \\-\\-help` prints them.\n")
set(cases "")
set(choice_cases "")
foreach(opt IN LISTS top_options)
  if(DEFINED top_choices_${opt})
    string(APPEND choice_cases "    \" ${opt}\") words=\"${top_choices_${opt}}\" ;;\n")
  endif()
endforeach()
foreach(sub IN LISTS top_subcommands)
  run_help(help ${sub})
  to_roff("${help}" roff)
  string(APPEND include ".SS \"isotile ${sub}\"\n.nf\n${roff}.fi\n")
  parse_help("${help}" sub)
  # Options of the program itself are accepted after a command too (CLI11's fallthrough).
  set(all_options ${sub_options} ${top_options})
  list(REMOVE_DUPLICATES all_options)
  list(JOIN all_options " " words)
  string(APPEND cases "    ${sub}) opts=\"${words}\" ;;\n")
  foreach(opt IN LISTS sub_options)
    if(DEFINED sub_choices_${opt})
      string(APPEND choice_cases "    \"${sub} ${opt}\") words=\"${sub_choices_${opt}}\" ;;\n")
    endif()
  endforeach()
endforeach()

file(WRITE "${OUT}/commands.h2m" "${include}")
execute_process(
  COMMAND "${HELP2MAN}" --no-info --no-discard-stderr --section 1
          --name "isosurface meshes from volumes on uniform grids"
          --include "${OUT}/commands.h2m" --include "${CMAKE_CURRENT_LIST_DIR}/isotile.h2m"
          --output "${OUT}/isotile.1" "${ISOTILE}"
  RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "help2man failed (${rc})")
endif()
# Debian compresses man pages with gzip -9n (no name or time stamp: reproducible).
execute_process(COMMAND gzip -9nf "${OUT}/isotile.1" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "gzip failed (${rc})")
endif()

list(JOIN top_subcommands "|" sub_pattern)
list(JOIN top_subcommands " " sub_words)
list(JOIN top_options " " top_words)
file(WRITE "${OUT}/isotile.bash" "# bash completion for isotile, generated from its --help at build time.
_isotile() {
  local cur=\${COMP_WORDS[COMP_CWORD]} prev=\${COMP_WORDS[COMP_CWORD-1]} cmd= opts words i
  for ((i = 1; i < COMP_CWORD; i++)); do
    case \${COMP_WORDS[i]} in
      ${sub_pattern}) cmd=\${COMP_WORDS[i]}; break ;;
    esac
  done
  case \"\$cmd \$prev\" in
${choice_cases}  esac
  if [[ -n \$words ]]; then
    COMPREPLY=(\$(compgen -W \"\$words\" -- \"\$cur\"))
    return
  fi
  case \$cmd in
${cases}    *) opts=\"${top_words}\" ;;
  esac
  if [[ \$cur == -* ]]; then
    COMPREPLY=(\$(compgen -W \"\$opts\" -- \"\$cur\"))
  elif [[ -z \$cmd ]]; then
    COMPREPLY=(\$(compgen -W \"${sub_words}\" -- \"\$cur\"))
  else
    COMPREPLY=(\$(compgen -f -- \"\$cur\"))
  fi
}
complete -o filenames -F _isotile isotile
")
