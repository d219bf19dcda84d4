#!/usr/bin/env bash
# Installs what isotile needs from Debian 12's packages, then configures and builds it.
#
#   ./setup.sh                 install, configure and build into build/ (Release)
#   ./setup.sh --bench         also the benchmarks and their peers (VTK: a large download;
#                              meshoptimizer)
#   ./setup.sh --sanitize      ASan + UBSan build into build-asan/
#   ./setup.sh --tsan          ThreadSanitizer build into build-tsan/, against a TBB built from
#                              Debian's own onetbb source with TSan (Debian's libtbb is not
#                              instrumented, so TSan cannot see its synchronisation)
#   ./setup.sh --no-install    skip the package step (packages already present)
#
# The MeshLab plugin is built against MeshLab 2020.09's own headers, taken from Debian's source
# package of the installed meshlab (`apt-get source`, which needs a deb-src entry: added when
# missing) into build-deps/, outside every build folder so that all builds share it.
#
# Safe to run again: installed packages are skipped and the build is incremental.
set -euo pipefail
cd "$(dirname "$0")"

bench=0 install=1 tsan=0 sanitize=0 build_dir=build extra=()
for arg in "$@"; do
  case "$arg" in
    --bench) bench=1 ;;
    # -O1 -g1: about half the compile time of -O2 -g under the sanitizers (measured on the heaviest
    # file, extract/macet.cpp), and line tables are what the reports' stack traces need. Without the
    # Python module and the MeshLab plugin: neither can load into Debian's uninstrumented python3
    # and meshlabserver (the Qt-free part of the plugin, isotile_meshlab_job, is still built).
    --sanitize) sanitize=1; build_dir=build-asan
      extra+=(-DISOTILE_SANITIZE=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo
              "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
              "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DISOTILE_PYTHON=OFF
              -DISOTILE_MESHLAB_SOURCE=) ;;
    # Without the Python module, as --sanitize: an instrumented module cannot load into Debian's
    # python3 (libtsan cannot take its static TLS block in a process that did not start with it).
    --tsan) tsan=1; build_dir=build-tsan
      extra+=(-DISOTILE_TSAN=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo -DISOTILE_PYTHON=OFF) ;;
    --no-install) install=0 ;;
    *) echo "setup.sh: unknown option '$arg'" >&2; exit 2 ;;
  esac
done

packages=(
  cmake ninja-build g++ pkg-config python3
  libtbb-dev libeigen3-dev zlib1g-dev libdeflate-dev nlohmann-json3-dev libcli11-dev
  libteem-dev libopenvdb-dev libboost-iostreams-dev libcgal-dev libgmp-dev libmpfr-dev
  libgtest-dev libopenmesh-dev libinsighttoolkit5-dev libgdcm-dev libopenmpi-dev openmpi-bin
  libegl-dev libegl-mesa0 libgl1-mesa-dri libgl1-mesa-dev libosmesa6-dev python3-glad glslang-tools
  libpng-dev
  meshlab qtbase5-dev libqt5opengl5-dev libglew-dev xvfb xauth dpkg-dev
  help2man
  python3-dev python3-numpy pybind11-dev python3-pybind11 python3-pytest python3-skimage
  python3-meshio python3-vtk9
)
if [ "$bench" = 1 ]; then
  packages+=(libbenchmark-dev libvtk9-dev libmeshoptimizer-dev)
  extra+=(-DISOTILE_BUILD_BENCHMARKS=ON)
fi

sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"

if [ "$install" = 1 ]; then
  missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "setup.sh: installing ${missing[*]}" >&2
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
fi

# Debian's source packages (MeshLab's headers, onetbb for TSan) need a deb-src entry.
ensure_deb_src() {
  if ! grep -rqs '^Types:.*deb-src' /etc/apt/sources.list.d/ && ! grep -qs '^deb-src' /etc/apt/sources.list; then
    sed 's/^Types: deb$/Types: deb-src/' /etc/apt/sources.list.d/debian.sources |
      $sudo tee /etc/apt/sources.list.d/isotile-deb-src.sources >/dev/null
    $sudo apt-get update -qq
  fi
}

# MeshLab's plugin API and vcglib, exactly as Debian built the installed meshlab.
meshlab_src="$PWD/build-deps/meshlab"
if [ "$install" = 1 ] && [ ! -f "$meshlab_src/.complete" ]; then
  ensure_deb_src
  rm -rf "$meshlab_src" && mkdir -p "$meshlab_src"
  if ! (cd "$meshlab_src" && apt-get source -qq meshlab >/dev/null 2>&1); then
    echo "setup.sh: could not fetch MeshLab's source package (apt-get source meshlab)" >&2
    exit 1
  fi
  touch "$meshlab_src/.complete"
fi
if [ "$sanitize" = 0 ] && [ -f "$meshlab_src/.complete" ]; then
  tree=$(find "$meshlab_src" -mindepth 1 -maxdepth 1 -type d -name 'meshlab-*' | head -n 1)
  [ -n "$tree" ] && extra+=(-DISOTILE_MESHLAB_SOURCE="$tree")
fi

if [ "$tsan" = 1 ]; then
  tbb_prefix="$PWD/$build_dir/tbb-tsan"
  if [ ! -f "$tbb_prefix/lib/cmake/TBB/TBBConfig.cmake" ]; then
    ensure_deb_src
    src="$PWD/$build_dir/onetbb-src"
    rm -rf "$src" && mkdir -p "$src"
    if ! (cd "$src" && apt-get source -qq onetbb >/dev/null 2>&1); then
      echo "setup.sh: could not fetch TBB's source package (apt-get source onetbb)" >&2
      exit 1
    fi
    tbb_dir=$(find "$src" -mindepth 1 -maxdepth 1 -type d -name 'onetbb-*' | head -n 1)
    cmake -S "$tbb_dir" -B "$src/build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTBB_TEST=OFF \
      -DTBB_STRICT=OFF -DTBB_SANITIZE=thread -DCMAKE_INSTALL_PREFIX="$tbb_prefix" >/dev/null
    cmake --build "$src/build" >/dev/null
    cmake --install "$src/build" >/dev/null
  fi
  extra+=(-DCMAKE_PREFIX_PATH="$tbb_prefix")
fi

cmake -S . -B "$build_dir" -G Ninja "${extra[@]}" >/dev/null
cmake --build "$build_dir" -j "$(nproc)"
