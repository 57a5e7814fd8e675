# `cmake --install build [--prefix DIR]`: the libraries, their headers (include/stokesvdb/<layer>/),
# the stokesvdb program, the shipped scenes with their schema and meshes (share/stokesvdb/scenes,
# share/stokesvdb/data/meshes: the scenes name their meshes as ../data/meshes/...; `stokesvdb run
# NAME` finds them there), and a CMake package so that another project can
#
#   find_package(StokesVDB REQUIRED)
#   target_link_libraries(app PRIVATE StokesVDB::stokesvdb)   # #include <stokesvdb/stokesvdb.h>
#
# (examples/drop_ball builds against it; tests/CMakeLists.txt tests that). The layers' targets keep
# their names under the StokesVDB:: namespace too: stokes_parallel, stokes_solver, stokes_kernels and
# stokes_sim_particles (header-only layers), stokes_sparse_grid (the OpenVDB trees it stores, compiled once),
# stokes_systems (solveStep compiled for 2D and 3D),
# stokes_analytic, stokes_sim_geometry, stokes_sim_scene, stokes_sim_output and stokes_sim (static
# libraries).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(STOKES_INSTALL_INCLUDEDIR ${CMAKE_INSTALL_INCLUDEDIR}/stokesvdb)
set(STOKES_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/StokesVDB)

# StokesVDB::stokesvdb: the whole library behind one target, with the umbrella header
# <stokesvdb/stokesvdb.h> (include/stokesvdb/stokesvdb.h)
add_library(stokesvdb_library INTERFACE)
set_target_properties(stokesvdb_library PROPERTIES EXPORT_NAME stokesvdb)
target_link_libraries(stokesvdb_library INTERFACE stokes_sim stokes_analytic)
target_include_directories(stokesvdb_library INTERFACE $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
                                                       $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
install(FILES ${PROJECT_SOURCE_DIR}/include/stokesvdb/stokesvdb.h DESTINATION ${STOKES_INSTALL_INCLUDEDIR})

set(STOKES_INSTALLED_TARGETS stokesvdb_library stokes_options stokes_parallel stokes_solver stokes_kernels stokes_sparse_grid stokes_systems
    stokes_analytic stokes_sim_particles stokes_sim_ranks stokes_sim_geometry stokes_sim_scene stokes_sim_output stokes_sim)
if(STOKES_WITH_PETSC)
  list(APPEND STOKES_INSTALLED_TARGETS stokes_petsc)
endif()
install(TARGETS ${STOKES_INSTALLED_TARGETS}
        EXPORT StokesVDBTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${STOKES_INSTALL_INCLUDEDIR})
install(TARGETS stokesvdb RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/scenes/ DESTINATION ${CMAKE_INSTALL_DATADIR}/stokesvdb/scenes)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/data/meshes/ DESTINATION ${CMAKE_INSTALL_DATADIR}/stokesvdb/data/meshes
        FILES_MATCHING PATTERN "*.obj" PATTERN "SOURCES.md")
foreach(layer parallel solver kernels sparse_grid analytic sim)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${layer} DESTINATION ${STOKES_INSTALL_INCLUDEDIR}
          FILES_MATCHING PATTERN "*.h")
endforeach()
install(EXPORT StokesVDBTargets NAMESPACE StokesVDB:: DESTINATION ${STOKES_INSTALL_CMAKEDIR})

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/StokesVDBConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/StokesVDBConfig.cmake
                              INSTALL_DESTINATION ${STOKES_INSTALL_CMAKEDIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/StokesVDBConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/StokesVDBConfig.cmake ${PROJECT_BINARY_DIR}/StokesVDBConfigVersion.cmake
        DESTINATION ${STOKES_INSTALL_CMAKEDIR})
