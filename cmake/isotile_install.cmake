# Install rules, by component (docs/install.md):
#   cli      bin/isotile, its man page and bash completion
#   dev      the static libraries, their public headers under include/isotile/, and the CMake
#            package (find_package(isotile CONFIG): isotile::core, isotile::tiler, isotile::gl)
#   meshlab  the MeshLab plugin, in MeshLab's own plugin folder (meshlab_plugin/CMakeLists.txt)
#   python   the isotile Python package in lib/python3/dist-packages (python/CMakeLists.txt)
# Included by the top-level CMakeLists.txt after every part has defined its targets.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(ISOTILE_CMAKE_DIR "${CMAKE_INSTALL_LIBDIR}/cmake/isotile")
# One export set per component (isotile_<component>Targets.cmake), each with its find_dependency()
# lines (ISOTILE_FIND_<component>), so that the config loads, and finds the dependencies of, only
# the components asked for: CMake checks every imported target's link interface when it loads an
# export set. ISOTILE_COMPONENTS lists them in the order they are loaded.
set(ISOTILE_COMPONENTS "")
set(ISOTILE_DEV_DEBIAN_DEPENDS "")

# Exports one library as isotile::<NAME> in the dev component.
#   HEADERS        its public headers, relative to the source root; installed under
#                  include/isotile/ with the same paths, so `#include "core/mesh/mesh.h"` works
#                  the same in the tree and installed
#   FIND_PACKAGES  what its exported link interface names (a static library's private
#                  dependencies are linked by its users too), one find_dependency() argument
#                  string each, e.g. "TBB CONFIG"
#   DEBIAN_DEPENDS the Debian -dev packages that provide those (libisotile-dev's Depends)
#   INTERNAL       a helper target that is only exported because a library's link interface
#                  names it (no component of its own, no headers)
#   COMPONENT      with INTERNAL: the component whose library links it (its export set)
function(isotile_export_library target)
  cmake_parse_arguments(arg "INTERNAL" "NAME;COMPONENT" "HEADERS;FIND_PACKAGES;DEBIAN_DEPENDS"
                        ${ARGN})
  set(component ${arg_NAME})
  if(arg_INTERNAL)
    set(component ${arg_COMPONENT})
  else()
    list(APPEND ISOTILE_COMPONENTS ${component})
    set(ISOTILE_COMPONENTS "${ISOTILE_COMPONENTS}" PARENT_SCOPE)
  endif()
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${arg_NAME})
  # Include folders inside the source or build tree mean nothing once installed.
  get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
  if(dirs)
    set(wrapped "")
    foreach(dir IN LISTS dirs)
      cmake_path(IS_PREFIX PROJECT_SOURCE_DIR "${dir}" NORMALIZE in_source)
      cmake_path(IS_PREFIX PROJECT_BINARY_DIR "${dir}" NORMALIZE in_build)
      if(in_source OR in_build)
        set(dir "$<BUILD_INTERFACE:${dir}>")
      endif()
      list(APPEND wrapped "${dir}")
    endforeach()
    set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${wrapped}")
  endif()
  set(headers "")
  if(arg_HEADERS)
    target_sources(${target} PUBLIC FILE_SET isotile_headers TYPE HEADERS
                   BASE_DIRS "${PROJECT_SOURCE_DIR}" FILES ${arg_HEADERS})
    set(headers FILE_SET isotile_headers DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}/isotile"
                COMPONENT dev)
  endif()
  install(TARGETS ${target} EXPORT isotile_${component}Targets
          ARCHIVE DESTINATION "${CMAKE_INSTALL_LIBDIR}" COMPONENT dev ${headers}
          INCLUDES DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}/isotile")
  foreach(pkg IN LISTS arg_FIND_PACKAGES)
    string(APPEND ISOTILE_FIND_${component} "  find_dependency(${pkg})\n")
  endforeach()
  set(ISOTILE_FIND_${component} "${ISOTILE_FIND_${component}}" PARENT_SCOPE)
  list(APPEND ISOTILE_DEV_DEBIAN_DEPENDS ${arg_DEBIAN_DEPENDS})
  set(ISOTILE_DEV_DEBIAN_DEPENDS "${ISOTILE_DEV_DEBIAN_DEPENDS}" PARENT_SCOPE)
endfunction()

# The exported libraries: the one place to add another (docs/install.md). Dependencies in the
# order the config must find them: TBB's own config before anything that could find OpenVDB's
# FindTBB module.
isotile_export_library(isotile_teem NAME teem INTERNAL COMPONENT core DEBIAN_DEPENDS libteem-dev)
isotile_export_library(isotile_core NAME core
  HEADERS
    core/errors.h
    core/extract/cell_mask.h
    core/extract/cell_ranges.h
    core/extract/dual_contouring.h
    core/extract/extract.h
    core/extract/macet.h
    core/mesh/mesh.h
    core/mesh/mesh_frame.h
    core/mesh/mesh_io.h
    core/mesh/mesh_quality.h
    core/mesh/mesh_topology.h
    core/progress.h
    core/simplify/quadric.h
    core/simplify/simplify.h
    core/volume/otsu_isovalue.h
    core/volume/procedural_fields.h
    core/volume/scalar_type.h
    core/volume/volume.h
    core/volume/volume_io.h
    core/version.h
  FIND_PACKAGES "TBB CONFIG" ZLIB "Eigen3 NO_MODULE" OpenMesh
  DEBIAN_DEPENDS libtbb-dev zlib1g-dev libeigen3-dev libopenmesh-dev libgmp-dev libmpfr-dev
                 libdeflate-dev)
# The OpenVDB reader's library, linked privately by core (after TBB's config is found).
isotile_export_library(isotile_vdb NAME vdb INTERNAL COMPONENT core FIND_PACKAGES OpenVDB
  DEBIAN_DEPENDS libopenvdb-dev libboost-iostreams-dev)
# The ITK readers' library, linked privately by core: consumers of the static core need ITK's
# libraries too. Debian's ITK config runs FindHDF5, whose checks need the C language: enabled for
# the consumer, so that a C++-only project can use the package.
if(ISOTILE_ITK)
  string(APPEND ISOTILE_FIND_core
         "  if(NOT CMAKE_C_COMPILER_LOADED)\n    enable_language(C)\n  endif()\n")
  isotile_export_library(isotile_itk NAME itk INTERNAL COMPONENT core
    FIND_PACKAGES "ITK 5.2 CONFIG COMPONENTS ITKIOImageBase ITKIONIFTI ITKIOMeta ITKIOGDCM ITKIOTIFF"
    DEBIAN_DEPENDS libinsighttoolkit5-dev)
else()
  isotile_export_library(isotile_itk NAME itk INTERNAL COMPONENT core)
endif()
# The tiler's pipeline hands its statistics out as nlohmann::json (header-only); it links MPI's C
# library when built with distributed extraction.
set(tiler_packages nlohmann_json)
set(tiler_debian nlohmann-json3-dev)
if(ISOTILE_HAVE_MPI)
  list(APPEND tiler_packages "MPI COMPONENTS C")
  list(APPEND tiler_debian libopenmpi-dev)
endif()
isotile_export_library(isotile_tiler NAME tiler
  HEADERS
    tiler/brick_plan.h
    tiler/input_options.h
    tiler/option_names.h
    tiler/pipeline.h
    tiler/stats_json.h
    tiler/tiled_extract.h
    tiler/volume_source.h
  FIND_PACKAGES ${tiler_packages}
  DEBIAN_DEPENDS ${tiler_debian})
if(TARGET isotile_gl)
  isotile_export_library(isotile_glad NAME glad INTERNAL COMPONENT gl)
  isotile_export_library(isotile_gl NAME gl
    HEADERS shaders/gl_backends.h shaders/stage_clock.h
    FIND_PACKAGES "OpenGL COMPONENTS EGL" PNG
    DEBIAN_DEPENDS libegl-dev libpng-dev)
endif()

# Each component's block of the config: its dependencies, then its targets.
set(ISOTILE_LOAD_COMPONENTS "")
foreach(component IN LISTS ISOTILE_COMPONENTS)
  install(EXPORT isotile_${component}Targets NAMESPACE isotile:: DESTINATION "${ISOTILE_CMAKE_DIR}"
          COMPONENT dev)
  string(APPEND ISOTILE_LOAD_COMPONENTS
         "if(\"${component}\" IN_LIST _isotile_load)\n${ISOTILE_FIND_${component}}"
         "  include(\"\${CMAKE_CURRENT_LIST_DIR}/isotile_${component}Targets.cmake\")\n"
         "  set(isotile_${component}_FOUND TRUE)\nendif()\n")
endforeach()
configure_package_config_file(
  "${CMAKE_CURRENT_LIST_DIR}/isotileConfig.cmake.in"
  "${PROJECT_BINARY_DIR}/cmake/isotileConfig.cmake"
  INSTALL_DESTINATION "${ISOTILE_CMAKE_DIR}")
# 0.x: a new minor version may change the interface.
write_basic_package_version_file("${PROJECT_BINARY_DIR}/cmake/isotileConfigVersion.cmake"
                                 COMPATIBILITY SameMinorVersion)
install(FILES "${PROJECT_BINARY_DIR}/cmake/isotileConfig.cmake"
              "${PROJECT_BINARY_DIR}/cmake/isotileConfigVersion.cmake"
        DESTINATION "${ISOTILE_CMAKE_DIR}" COMPONENT dev)

# The command line, its man page and its bash completion, both generated from its own --help.
install(TARGETS isotile RUNTIME DESTINATION "${CMAKE_INSTALL_BINDIR}" COMPONENT cli)
install(TARGETS ${ISOTILE_READER_MODULES} LIBRARY DESTINATION "${CMAKE_INSTALL_LIBDIR}/isotile"
        COMPONENT cli)
find_program(ISOTILE_HELP2MAN help2man)
if(ISOTILE_HELP2MAN)
  set(docs "${PROJECT_BINARY_DIR}/cli-docs")
  add_custom_command(
    OUTPUT "${docs}/isotile.1.gz" "${docs}/isotile.bash"
    COMMAND "${CMAKE_COMMAND}" "-DISOTILE=$<TARGET_FILE:isotile>" "-DHELP2MAN=${ISOTILE_HELP2MAN}"
            "-DOUT=${docs}" -P "${CMAKE_CURRENT_LIST_DIR}/isotile_cli_docs.cmake"
    DEPENDS isotile "${CMAKE_CURRENT_LIST_DIR}/isotile_cli_docs.cmake"
            "${CMAKE_CURRENT_LIST_DIR}/isotile.h2m"
    COMMENT "Generating the isotile man page and bash completion from its --help"
    VERBATIM)
  add_custom_target(isotile_cli_docs ALL DEPENDS "${docs}/isotile.1.gz" "${docs}/isotile.bash")
  install(FILES "${docs}/isotile.1.gz" DESTINATION "${CMAKE_INSTALL_MANDIR}/man1" COMPONENT cli)
  install(FILES "${docs}/isotile.bash" RENAME isotile
          DESTINATION "${CMAKE_INSTALL_DATADIR}/bash-completion/completions" COMPONENT cli)
else()
  message(STATUS "isotile man page and bash completion: not built; missing help2man "
                 "(Debian package help2man; ./setup.sh installs it)")
endif()

include("${CMAKE_CURRENT_LIST_DIR}/isotile_packaging.cmake")
