#!/usr/bin/env bash
# Installing isotile the ways its users do (docs/install.md). Run by ctest (tests/CMakeLists.txt):
#
#   check_install.sh prefix SOURCE BUILD VERSION SANITIZED MESHLAB
#     `cmake --install` into a temporary prefix (cli, dev; meshlab under DESTDIR), the man page and
#     bash completion, then tests/install_consumer (a separate CMake project) builds README.md's
#     C++ example with find_package(isotile) and runs it: its meshes must be the installed CLI's.
#   check_install.sh deb SOURCE BUILD VERSION SANITIZED MESHLAB
#     `cpack -G DEB`, `apt-get install` of the packages, `isotile demo` from PATH, `dpkg -L` only
#     under /usr, the filter in Debian's own meshlabserver, then purges them (and anything apt
#     pulled in), leaving the machine's package set as it was, on failure too.
#
# Exit 77 (ctest: skipped) with the reason where a run cannot do it by its nature; where
# ISOTILE_STRICT_SKIPS names "packaging" (or "all") a missing precondition fails instead.
set -euo pipefail
mode=$1 src=$2 build=$3 version=$4 sanitized=$5 meshlab=$6 python=${7:-0}

fail() { echo "check_install: FAILED: $*" >&2; exit 1; }
skip() {
  case ",${ISOTILE_STRICT_SKIPS:-}," in
    *,packaging,* | *,all,*) fail "cannot run (packaging is required by ISOTILE_STRICT_SKIPS): $*" ;;
  esac
  echo "check_install: SKIPPED: $*"
  exit 77
}
if [ "$sanitized" = 1 ]; then
  # Not a missing dependency: this pass cannot do it, so no strictness applies.
  echo "check_install: SKIPPED: a sanitizer build's libraries need the sanitizer runtime in" \
    "every program that links them, and its packages are not what users install; the Release" \
    "pass runs this test"
  exit 77
fi

tmp=$(mktemp -d "${TMPDIR:-/tmp}/isotile_install.XXXXXX")
chmod 755 "$tmp"  # apt reads the .deb files as its own unprivileged user
cleanup_tmp() { rm -rf "$tmp"; }
trap cleanup_tmp EXIT
nucleon="$src/tests/data/nucleon_41x41x41_uint8.raw.gz"

now_ms() { echo $(($(date +%s%N) / 1000000)); }
# Faces and vertices of a mesh, as `isotile quality --json` counts them.
counts() {
  "$1" -q quality --json "$2" |
    python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["triangles"], j["vertices"])'
}

# The installed program ($1) reads MetaImage and OpenVDB input through the modules it loads from
# <libdir>/isotile: a small MetaImage volume, and a file that only the OpenVDB module itself can
# call "not a readable OpenVDB file" (without the module the error names the missing module).
check_reader_modules() {
  local dir="$tmp/modules" out
  mkdir -p "$dir"
  python3 -c 'import sys; sys.stdout.buffer.write(bytes(i % 7 * 30 for i in range(512)))' >"$dir/v.raw"
  printf 'ObjectType = Image\nNDims = 3\nDimSize = 8 8 8\nElementType = MET_UCHAR\nElementDataFile = v.raw\n' \
    >"$dir/v.mhd"
  if out=$("$1" -q info --json "$dir/v.mhd" 2>&1); then
    python3 -c 'import json,sys; assert json.loads(sys.argv[1])["dims"] == [8, 8, 8]' "$out" ||
      fail "the installed isotile read the MetaImage volume as $out"
  else
    grep -q "ISOTILE_ITK=OFF" <<<"$out" || fail "the installed isotile on MetaImage: $out"
  fi
  echo "not OpenVDB" >"$dir/bad.vdb"
  out=$("$1" -q extract "$dir/bad.vdb" --iso 0 -o "$dir/bad.ply" 2>&1) &&
    fail "the installed isotile read a file that is not OpenVDB"
  grep -q "not a readable OpenVDB file" <<<"$out" || fail "the installed isotile on .vdb: $out"
  echo "check_install: $1 read MetaImage and OpenVDB input through its modules"
}

# The installed Python module (under $1 on sys.path, or Debian's own dist-packages when empty),
# in Debian's python3: its mesh of a small volume has the installed program's face count, and it
# loads the installed OpenVDB reader module.
check_python_module() {
  local dir=$1 want got
  (cd "$tmp" && "$2" -q extract "$nucleon" --iso 49.5 -o py-cli.ply)
  read -r want _ <<<"$(counts "$2" "$tmp/py-cli.ply")"
  got=$(cd "$tmp" && PYTHONPATH="$dir" /usr/bin/python3 -c '
import gzip, sys, numpy as np, isotile
where = sys.argv[2] or "/usr/lib/python3/dist-packages/"
assert isotile.__file__.startswith(where), isotile.__file__
vol = np.frombuffer(gzip.open(sys.argv[1]).read(), np.uint8).reshape(41, 41, 41)
# The OpenVDB reader module, found from the installed extension (tiler/reader_modules.cpp):
# only the module itself calls this file "not a readable OpenVDB file".
open("bad.vdb", "w").write("not OpenVDB\n")
try:
    isotile.read_volume("bad.vdb")
    raise SystemExit("the installed module read a file that is not OpenVDB")
except (OSError, ValueError) as e:
    assert "not a readable OpenVDB file" in str(e), e
print(len(isotile.marching_cubes(vol, 49.5)[1]))' "$nucleon" "$dir") ||
    fail "import isotile from ${dir:-dist-packages}"
  [ "$got" = "$want" ] || fail "the installed module's mesh has $got faces, the program's $want"
  echo "check_install: the Python module from ${dir:-dist-packages}: $got faces, as the program's"
}

if [ "$mode" = prefix ]; then
  prefix="$tmp/prefix"
  for component in cli dev; do
    cmake --install "$build" --prefix "$prefix" --component "$component" >/dev/null
  done
  [ -x "$prefix/bin/isotile" ] || fail "no bin/isotile in the cli component"
  out=$(PATH="$prefix/bin:$PATH" isotile --version)
  [ "$out" = "isotile $version" ] || fail "isotile --version printed '$out', not 'isotile $version'"
  check_reader_modules "$prefix/bin/isotile"

  # The man page holds every subcommand's own options, the completion completes them.
  man="$prefix/share/man/man1/isotile.1.gz"
  [ -f "$man" ] || fail "no man page in the cli component (is help2man installed?)"
  subs=$("$prefix/bin/isotile" --help | sed -n '/^Subcommands:/,$p' | awk 'NR > 1 && /^  [a-z]/ {print $1}')
  [ "$(echo "$subs" | wc -w)" -ge 5 ] || fail "found only '$subs' in isotile --help"
  roff=$(zcat "$man")
  for sub in $subs; do
    grep -q "^\.SS \"isotile $sub\"" <<<"$roff" || fail "man page lacks a section for '$sub'"
  done
  grep -q 'dc\\-solver' <<<"$roff" || fail "man page lacks extract's --dc-solver"
  for section in "EXIT STATUS" ENVIRONMENT FILES EXAMPLES; do
    grep -q "^\.SH \"\?$section\"\?\$" <<<"$roff" || fail "man page lacks its $section section"
  done
  grep -q 'ISOTILE_GL' <<<"$roff" || fail "man page's ENVIRONMENT lacks ISOTILE_GL"
  completion="$prefix/share/bash-completion/completions/isotile"
  [ -f "$completion" ] || fail "no bash completion in the cli component"
  complete_words() {
    bash -c 'source "$1"; shift; COMP_WORDS=("$@"); COMP_CWORD=$(($# - 1)); _isotile
             echo "${COMPREPLY[*]}"' _ "$completion" "$@"
  }
  [ "$(complete_words isotile ext)" = extract ] || fail "completion of 'isotile ext'"
  [ "$(complete_words isotile extract --dc-so)" = --dc-solver ] ||
    fail "completion of 'isotile extract --dc-so': '$(complete_words isotile extract --dc-so)'"
  [ "$(complete_words isotile extract --method ma)" = macet ] || fail "completion of --method ma"
  [ "$(complete_words isotile simplify --max)" = --max-error ] || fail "completion of --max"

  if [ "$meshlab" = 1 ]; then
    # Debian's MeshLab folder whatever the prefix: DESTDIR shows where it goes.
    DESTDIR="$tmp/stage" cmake --install "$build" --prefix "$prefix" --component meshlab >/dev/null
    plugin=$(find "$tmp/stage" -name libfilter_isotile.so)
    case "$plugin" in
      "$tmp"/stage/usr/lib/*/meshlab/plugins/libfilter_isotile.so) ;;
      *) fail "meshlab component installed '$plugin', not into /usr/lib/<arch>/meshlab/plugins" ;;
    esac
  fi

  if [ "$python" = 1 ]; then
    cmake --install "$build" --prefix "$prefix" --component python >/dev/null
    check_python_module "$prefix/lib/python3/dist-packages" "$prefix/bin/isotile"
  fi

  # README.md's C++ example, as it stands there, in main(), reading a small real volume.
  example="$tmp/readme_example.cpp"
  awk '/^```cpp$/ { f = 1; next } /^```$/ { if (f) exit } f' "$src/README.md" >"$tmp/body"
  grep -q 'engine_256x256x128_uint8.raw.gz' "$tmp/body" || fail "README.md's C++ example changed"
  {
    grep '^#include' "$tmp/body"
    echo 'int main() {'
    grep -v '^#include' "$tmp/body" | sed "s|\"engine_256x256x128_uint8.raw.gz\"|\"$nucleon\"|"
    echo '}'
  } >"$example"
  start=$(now_ms)
  cmake -S "$src/tests/install_consumer" -B "$tmp/consumer" -G Ninja \
    -DCMAKE_PREFIX_PATH="$prefix" -DREADME_EXAMPLE="$example" >"$tmp/configure.log" ||
    { cat "$tmp/configure.log"; fail "configuring the consumer project"; }
  found=$(sed -n 's/^isotile_DIR:PATH=//p' "$tmp/consumer/CMakeCache.txt")
  case "$found" in "$prefix"/lib/*cmake/isotile) ;; *) false ;; esac || fail "find_package found isotile in '$found'"
  cmake --build "$tmp/consumer" >"$tmp/build.log" ||
    { cat "$tmp/build.log"; fail "building the consumer project"; }
  echo "check_install: consumer configured and built in $(($(now_ms) - start)) ms"

  mkdir "$tmp/run"
  (cd "$tmp/run" && "$tmp/consumer/readme_example") || fail "README example exited with $?"
  isotile="$prefix/bin/isotile"
  (cd "$tmp/run" && "$isotile" -q extract "$nucleon" --iso 49.5 --normals -o cli.ply &&
    "$isotile" -q simplify engine.ply cli-small.ply --ratio 0.1)
  # The library and the installed CLI give the same meshes.
  cmp "$tmp/run/engine.ply" "$tmp/run/cli.ply" || fail "README example's engine.ply differs from the CLI's"
  read -r faces _ <<<"$(counts "$isotile" "$tmp/run/engine.ply")"
  read -r small_faces _ <<<"$(counts "$isotile" "$tmp/run/engine-small.ply")"
  [ "$faces" -gt 1000 ] || fail "README example's mesh has $faces faces"
  [ "$(counts "$isotile" "$tmp/run/engine-small.ply")" = "$(counts "$isotile" "$tmp/run/cli-small.ply")" ] ||
    fail "README example's engine-small.ply differs from the CLI's simplification"
  echo "check_install: README example: $faces faces, $small_faces after simplify --ratio 0.1"
  [ "$small_faces" -le $((faces / 10 + 2)) ] || fail "simplified to $small_faces of $faces faces"

  out=$("$tmp/consumer/all_headers") || fail "all_headers exited with $?"
  echo "$out"
  grep -Eq '^bricks ([2-9]|[1-9][0-9]+)$' <<<"$out" || fail "all_headers: no brick plan"
  if [ -f "$found/isotile_glTargets.cmake" ]; then
    grep -q '^gl backends registered$' <<<"$out" || fail "all_headers did not register GL"
  fi
  # A component the package lacks is named (check_required_components said only that
  # isotile_FOUND was false).
  mkdir -p "$tmp/bogus"
  printf '%s\n' 'cmake_minimum_required(VERSION 3.25)' 'project(bogus LANGUAGES CXX)' \
    'find_package(isotile 0.1 CONFIG REQUIRED COMPONENTS core bogus)' >"$tmp/bogus/CMakeLists.txt"
  if cmake -S "$tmp/bogus" -B "$tmp/bogus/b" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" \
    >"$tmp/bogus.log" 2>&1; then
    fail "find_package(isotile COMPONENTS core bogus) succeeded"
  fi
  grep -q "isotile has no component 'bogus'" "$tmp/bogus.log" ||
    { cat "$tmp/bogus.log"; fail "an unknown component is not named"; }
  # Asked for as optional, it is left not found and the rest loads.
  printf '%s\n' 'cmake_minimum_required(VERSION 3.25)' 'project(bogus LANGUAGES CXX)' \
    'find_package(isotile 0.1 CONFIG REQUIRED COMPONENTS core OPTIONAL_COMPONENTS bogus)' \
    'if(isotile_bogus_FOUND OR NOT TARGET isotile::core)' '  message(FATAL_ERROR "bogus found")' \
    'endif()' >"$tmp/bogus/CMakeLists.txt"
  cmake -S "$tmp/bogus" -B "$tmp/bogus/b2" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" \
    >"$tmp/bogus2.log" 2>&1 || { cat "$tmp/bogus2.log"; fail "OPTIONAL_COMPONENTS bogus failed"; }
  echo "check_install: an unknown component is named; an optional one is left not found"
  # COMPONENTS core loads core's export set alone and finds only its dependencies: a program of
  # the core library alone needs neither MPI, EGL, PNG nor nlohmann_json.
  mkdir -p "$tmp/core_only"
  printf '%s\n' 'cmake_minimum_required(VERSION 3.25)' 'project(core_only LANGUAGES CXX)' \
    'set(CMAKE_CXX_STANDARD 20)' \
    'find_package(isotile 0.1 CONFIG REQUIRED COMPONENTS core)' \
    'foreach(t IN ITEMS isotile::tiler isotile::gl MPI::MPI_C OpenGL::EGL PNG::PNG nlohmann_json::nlohmann_json)' \
    '  if(TARGET ${t})' '    message(FATAL_ERROR "COMPONENTS core loaded ${t}")' '  endif()' 'endforeach()' \
    'add_executable(core_only main.cpp)' 'target_link_libraries(core_only PRIVATE isotile::core)' \
    >"$tmp/core_only/CMakeLists.txt"
  printf '%s\n' '#include <iostream>' '#include "core/version.h"' \
    'int main() { std::cout << isotile::version() << "\n"; }' >"$tmp/core_only/main.cpp"
  { cmake -S "$tmp/core_only" -B "$tmp/core_only/b" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" &&
    cmake --build "$tmp/core_only/b"; } >"$tmp/core_only.log" 2>&1 ||
    { cat "$tmp/core_only.log"; fail "a project of COMPONENTS core alone"; }
  [ "$("$tmp/core_only/b/core_only")" = "$version" ] || fail "core_only printed another version"
  echo "check_install: COMPONENTS core loads core alone"
  echo "check_install: prefix install and consumer OK"
  exit 0
fi

[ "$mode" = deb ] || fail "unknown mode '$mode'"
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  sudo -n true 2>/dev/null || skip "installing packages needs root or password-less sudo"
  sudo="sudo -n"
fi
packages=(isotile libisotile-dev)
[ "$meshlab" = 1 ] && packages+=(meshlab-plugin-isotile)
[ "$python" = 1 ] && packages+=(python3-isotile)
installed() { dpkg-query -W -f='${db:Status-Status} ${Package}\n' 2>/dev/null | awk '$1 == "installed" {print $2}' | sort; }
present=$(installed)
for p in "${packages[@]}"; do
  grep -qx "$p" <<<"$present" && skip "package $p is installed already; this test would replace and purge it"
done
for p in /usr/bin/isotile /usr/lib/*/meshlab/plugins/libfilter_isotile.so \
  /usr/lib/python3/dist-packages/isotile; do
  [ -e "$p" ] && skip "$p exists (installed by hand?); this test would replace and remove it"
done

start=$(now_ms)
cpack -G DEB --config "$build/CPackConfig.cmake" -B "$tmp/debs" >"$tmp/cpack.log" 2>&1 ||
  { cat "$tmp/cpack.log"; fail "cpack -G DEB"; }
echo "check_install: cpack took $(($(now_ms) - start)) ms"
debs=()
for p in "${packages[@]}"; do
  deb=$(find "$tmp/debs" -maxdepth 1 -name "${p}_${version}-*_*.deb")
  [ -n "$deb" ] || fail "cpack made no ${p}_${version}-*.deb: $(ls "$tmp/debs")"
  debs+=("$deb")
  echo "check_install: $(basename "$deb"): Depends: $(dpkg-deb -f "$deb" Depends)"
  # The filter's messages name `isotile info`: the plugin's package recommends the CLI's.
  if [ "$p" = meshlab-plugin-isotile ]; then
    recommends=$(dpkg-deb -f "$deb" Recommends)
    grep -qE '(^|, )isotile($| |,)' <<<"$recommends" ||
      fail "$p recommends '$recommends', not isotile"
    echo "check_install: $(basename "$deb"): Recommends: $recommends"
  fi
done

apt=(env DEBIAN_FRONTEND=noninteractive $sudo apt-get -o DPkg::Lock::Timeout=900 -y -q)
# --no-install-recommends: the Recommends (Mesa's EGL driver, OSMesa) are not needed for the CPU
# path, and nothing is downloaded. What apt would install besides our packages (none where
# setup.sh ran) is purged afterwards too; only those packages are touched.
"${apt[@]}" -s install --no-install-recommends "${debs[@]}" >"$tmp/simulate.log" 2>&1 ||
  { cat "$tmp/simulate.log"; fail "apt-get -s install of the packages"; }
mapfile -t touched < <(awk '$1 == "Inst" {print $2}' "$tmp/simulate.log")
[ "${#touched[@]}" -gt 0 ] || fail "apt-get -s install would install nothing"
echo "check_install: apt installs ${touched[*]}"
restore() {
  local rc=$? left
  "${apt[@]}" purge "${touched[@]}" >"$tmp/purge.log" 2>&1 || cat "$tmp/purge.log" >&2
  left=$(installed | grep -xF "${touched[@]/#/-e}" || true)
  if [ -n "$left" ]; then
    echo "check_install: FAILED: still installed after the purge: $left" >&2
    rc=1
  fi
  rm -rf "$tmp"
  exit $rc
}
trap restore EXIT

"${apt[@]}" install --no-install-recommends "${debs[@]}" >"$tmp/install.log" 2>&1 ||
  { cat "$tmp/install.log"; fail "apt-get install of the packages"; }

[ "$(command -v isotile)" = /usr/bin/isotile ] || fail "isotile on PATH is '$(command -v isotile)'"
mkdir "$tmp/run"
(cd "$tmp/run" && isotile demo >demo.json) || fail "isotile demo exited with $?"
python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); assert j["triangles"] > 100000, j' \
  "$tmp/run/demo.json" || fail "isotile demo's statistics"
read -r demo_faces _ <<<"$(counts isotile "$tmp/run/isotile-demo.ply")"
echo "check_install: isotile demo from PATH: $demo_faces faces"
check_reader_modules isotile

for p in "${packages[@]}"; do
  # dpkg lists a package's root as "/.": every other path must be /usr or under it.
  bad=$(dpkg -L "$p" | grep -v -e '^/\.$' -e '^/usr$' -e '^/usr/' || true)
  [ -z "$bad" ] || fail "$p installs outside /usr: $bad"
done
grep -qx /usr/share/man/man1/isotile.1.gz <<<"$(dpkg -L isotile)" || fail "no man page in isotile"
# libisotile-dev's Depends give find_package(isotile) all it needs from /usr (the prefix test
# builds and runs the same project; configuring it is enough here).
echo 'int main() {}' >"$tmp/empty.cpp"
cmake -S "$src/tests/install_consumer" -B "$tmp/consumer" -G Ninja -DREADME_EXAMPLE="$tmp/empty.cpp" \
  >"$tmp/configure.log" 2>&1 || { cat "$tmp/configure.log"; fail "find_package(isotile) from /usr"; }
found=$(sed -n 's/^isotile_DIR:PATH=//p' "$tmp/consumer/CMakeCache.txt")
case "$found" in /usr/lib/*cmake/isotile) ;; *) fail "find_package found isotile in '$found'" ;; esac

[ "$python" = 1 ] && check_python_module "" /usr/bin/isotile

if [ "$meshlab" = 1 ]; then
  # Debian's own meshlabserver, with every system plugin, finds the filter from the package.
  sed "s|value=\"engine_256x256x128_uint8.raw.gz\"|value=\"$nucleon\"|" \
    "$src/meshlab_plugin/examples/isosurface.mlx" >"$tmp/run/script.mlx"
  grep -q "$nucleon" "$tmp/run/script.mlx" || fail "the example .mlx names another file"
  (cd "$tmp/run" && xvfb-run -a meshlabserver -s script.mlx -o layer.ply >server.log 2>&1) ||
    { cat "$tmp/run/server.log"; fail "meshlabserver with the installed plugin"; }
  (cd "$tmp/run" && isotile -q extract "$nucleon" --iso 49.5 --method macet -o cli.ply)
  [ "$(counts isotile "$tmp/run/layer.ply")" = "$(counts isotile "$tmp/run/cli.ply")" ] ||
    fail "meshlabserver's layer is not the CLI's mesh: $(counts isotile "$tmp/run/layer.ply")"
  echo "check_install: meshlabserver ran the installed filter"
fi
echo "check_install: packages built, installed, checked; purging them"
