# Debian packages with CPack (docs/install.md): `cpack -G DEB` in the build folder, or
# `cmake --build build --target package`, makes one .deb per install component:
#   isotile                 cli      /usr/bin/isotile, man page, bash completion
#   libisotile-dev          dev      static libraries, headers, CMake package
#   meshlab-plugin-isotile  meshlab  the plugin in Debian MeshLab's plugin folder
#   python3-isotile         python   the isotile module in Debian's dist-packages
# Depends: what dpkg-shlibdeps finds in the binaries, plus what it cannot see (below).
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME isotile)
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(ISOTILE_PACKAGE_MAINTAINER "isotile maintainers <maintainers@isotile.invalid>" CACHE STRING
    "Maintainer field of the Debian packages")
set(CPACK_PACKAGE_CONTACT "${ISOTILE_PACKAGE_MAINTAINER}")
set(CPACK_PACKAGE_FILE_NAME "isotile-${PROJECT_VERSION}")

# Everything under /usr. DESTDIR staging keeps the meshlab component's absolute destination
# (/usr/lib/<multiarch>/meshlab/plugins) inside the package instead of on the building machine.
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_INSTALL_PREFIX /usr)  # what DESTDIR staging installs under, whatever the build's prefix
set(CPACK_SET_DESTDIR ON)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_ALL cli dev)
if(TARGET filter_isotile)
  list(APPEND CPACK_COMPONENTS_ALL meshlab)
endif()
if(TARGET isotile_python)
  list(APPEND CPACK_COMPONENTS_ALL python)
endif()
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # name_version_arch.deb
set(CPACK_DEBIAN_PACKAGE_RELEASE 1)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_COMPRESSION_TYPE gzip)  # fast; the packages are built in CI

# Descriptions: the first line is the package's synopsis (no common summary, which CPack would
# put first).
set(CPACK_DEBIAN_CLI_PACKAGE_NAME isotile)
set(CPACK_DEBIAN_CLI_DESCRIPTION "isosurface meshes from volumes on uniform grids (command line)
The isotile program extracts isosurface meshes from volumes (raw, NRRD, OpenVDB) with Marching
Cubes, Macet or Dual Contouring, on the CPU or in OpenGL, in core or brick by brick, simplifies
them and measures their quality.")
# The GL backends dlopen OSMesa and need a Mesa EGL driver; without them the CPU extracts.
set(CPACK_DEBIAN_CLI_PACKAGE_RECOMMENDS "libegl-mesa0, libgl1-mesa-dri, libosmesa6")

set(CPACK_DEBIAN_DEV_PACKAGE_NAME libisotile-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
set(CPACK_DEBIAN_DEV_DESCRIPTION "isosurface meshes from volumes on uniform grids (C++ library)
Static libraries, headers and the CMake package of isotile: find_package(isotile) gives the
targets isotile::core, isotile::tiler and isotile::gl.")
# Static libraries: shlibdeps sees nothing; users link what the libraries link.
list(REMOVE_DUPLICATES ISOTILE_DEV_DEBIAN_DEPENDS)
list(JOIN ISOTILE_DEV_DEBIAN_DEPENDS ", " CPACK_DEBIAN_DEV_PACKAGE_DEPENDS)

set(CPACK_DEBIAN_MESHLAB_PACKAGE_NAME meshlab-plugin-isotile)
set(CPACK_DEBIAN_MESHLAB_PACKAGE_SECTION graphics)
set(CPACK_DEBIAN_MESHLAB_DESCRIPTION "isosurface meshes from volumes on uniform grids (MeshLab filters)
isotile's filters for MeshLab 2020.09: an isosurface from a volume file as a new layer, and
shape-preserving simplification.")
# The plugin API is MeshLab 2020.09's exactly; libmeshlab-common lives in MeshLab's private
# folder, which shlibdeps is told about but where it finds no shlibs entry.
set(CPACK_DEBIAN_MESHLAB_PACKAGE_DEPENDS "meshlab (>= 2020.09), meshlab (<< 2020.10)")
# The filter's messages point to `isotile info` for a volume's header and range.
set(CPACK_DEBIAN_MESHLAB_PACKAGE_RECOMMENDS isotile)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS_PRIVATE_DIRS "/usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/meshlab")

set(CPACK_DEBIAN_PYTHON_PACKAGE_NAME python3-isotile)
set(CPACK_DEBIAN_PYTHON_PACKAGE_SECTION python)
set(CPACK_DEBIAN_PYTHON_DESCRIPTION "isosurface meshes from volumes on uniform grids (Python 3)
isotile for NumPy arrays and volume files: marching_cubes as a drop-in for scikit-image's, with
Macet and Dual Contouring, extract() on the isotile program's pipeline, mesh quality measures and
simplification, on isotile's multithreaded C++ library.")
# The extension is built against this Python's ABI and imports NumPy; shlibdeps sees neither. It
# loads the OpenVDB and ITK reader modules of the isotile package, from the same build.
math(EXPR isotile_python_next "${Python_VERSION_MINOR} + 1")
set(CPACK_DEBIAN_PYTHON_PACKAGE_DEPENDS
    "python3 (>= ${Python_VERSION_MAJOR}.${Python_VERSION_MINOR}), python3 (<< ${Python_VERSION_MAJOR}.${isotile_python_next}), python3-numpy, isotile (= ${PROJECT_VERSION}-${CPACK_DEBIAN_PACKAGE_RELEASE})")

include(CPack)
