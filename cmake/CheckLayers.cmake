cmake_minimum_required(VERSION 3.20)
# cmake -DROOT=<tree> -P cmake/CheckLayers.cmake
# Fails when a module's sources or headers include a header of a module it may not depend on
# (one above it, or beside it), or when its CMakeLists.txt links one: the layering of
# docs/development.md's layout table, kept by a test.
#   core (the base: errors, angles, the cell size, CSV, atomic files, the thread pool, a frame's
#   volume and odometry, the road prior) under all;
#   osm <- raster <- io <- ingest (the preprocess report); intake (the frame in) and selfcal
#   (self-calibration's estimator), each on Eigen and core only, <- filter <- gpu (its CUDA backend),
#   offline (the offline baseline), uncertainty (a pose's, from its belief);
#   osm + raster <- io <- matcher; io + raster <- sim; io <- ros (ROS 2 bags); io + matcher + filter + offline + gpu + ros <- pipeline
#   (the driver); io + raster <- render (it draws what localize wrote); raster <- serve; pipeline <- python;
#   everything <- apps.
if(NOT ROOT)
  message(FATAL_ERROR "CheckLayers: set -DROOT=<source tree>")
endif()
set(allowed_core core)
set(allowed_osm core osm)
set(allowed_raster core osm raster)
set(allowed_intake core intake)
set(allowed_selfcal core selfcal)
set(allowed_filter core intake selfcal filter)
set(allowed_gpu core intake selfcal filter gpu)
set(allowed_offline core intake selfcal filter offline)
set(allowed_uncertainty core intake selfcal filter uncertainty)
set(allowed_ingest core osm raster io ingest)
set(allowed_io core osm raster io)
set(allowed_matcher core osm raster io matcher)
set(allowed_sim core osm raster io sim)
set(allowed_ros core osm raster io ros)
set(allowed_pipeline core osm raster intake selfcal filter offline uncertainty gpu io matcher ros pipeline)
set(allowed_render core osm raster io render)
set(allowed_serve core osm raster serve)
set(allowed_python core osm raster intake selfcal filter offline uncertainty gpu io matcher ros pipeline)
set(violations 0)
set(modules core osm raster intake selfcal filter offline uncertainty gpu ingest io matcher sim ros pipeline render serve python)
foreach(module IN LISTS modules)
  file(GLOB_RECURSE files "${ROOT}/${module}/*.cpp" "${ROOT}/${module}/*.hpp" "${ROOT}/${module}/*.cu")
  foreach(file IN LISTS files)
    file(STRINGS "${file}" includes REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]seqloc/[a-z_]+/")
    foreach(line IN LISTS includes)
      string(REGEX REPLACE "^.*seqloc/([a-z_]+)/.*$" "\\1" target "${line}")
      if(NOT target IN_LIST allowed_${module})
        file(RELATIVE_PATH rel "${ROOT}" "${file}")
        message(SEND_ERROR "${rel}: ${module} includes a header of ${target} (${module} may use: ${allowed_${module}})")
        math(EXPR violations "${violations} + 1")
      endif()
    endforeach()
  endforeach()
  # Its link lines: every seqloc::NAME its CMakeLists.txt names (seqloc_module's PUBLIC and
  # PRIVATE, target_link_libraries) must be a module it may use, or a dependency's wrapper
  # (seqloc::libosmium, seqloc::opencv, ...: not a module of the tree).
  if(EXISTS "${ROOT}/${module}/CMakeLists.txt")
    file(READ "${ROOT}/${module}/CMakeLists.txt" lists)
    string(REGEX REPLACE "#[^\n]*" "" lists "${lists}")
    string(REGEX MATCHALL "seqloc::[a-z_]+" linked "${lists}")
    foreach(entry IN LISTS linked)
      string(REPLACE "seqloc::" "" target "${entry}")
      if(target IN_LIST modules AND NOT target IN_LIST allowed_${module})
        message(SEND_ERROR "${module}/CMakeLists.txt: ${module} links ${target} (${module} may use: ${allowed_${module}})")
        math(EXPR violations "${violations} + 1")
      endif()
    endforeach()
  endif()
endforeach()
if(violations GREATER 0)
  message(FATAL_ERROR "${violations} include(s) or link(s) across the module layering")
endif()
message(STATUS "module layering: no include or link crosses it")
