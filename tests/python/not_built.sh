#!/bin/sh
# Run by ctest where CMake did not build the Python module (tests/CMakeLists.txt): a skip (exit
# 77), or a failure where ISOTILE_STRICT_SKIPS names "python" or "all".
why="the isotile Python module was not built (needs /usr/bin/python3, python3-dev, pybind11-dev, python3-pybind11, python3-numpy; or ISOTILE_PYTHON was OFF)"
case ",${ISOTILE_STRICT_SKIPS:-}," in
  *,python,* | *,all,*) echo "cannot run (python is required by ISOTILE_STRICT_SKIPS): $why" >&2; exit 1 ;;
esac
echo "skipped: $why"
exit 77
