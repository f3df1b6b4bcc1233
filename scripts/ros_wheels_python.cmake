# Included into a ROS package's CMake project (-DCMAKE_PROJECT_INCLUDE=...) when it builds
# against the ROS 2 wheels from PyPI: their exported targets name the include folders of the
# Python (and numpy) the wheels were built with, under /opt/python, which do not exist here.
# At the end of the project's configuration every imported target that names them names this
# Python's and numpy's instead (PYTHON_INCLUDE_DIRS, given by scripts/build-interfaces.sh).
# A build against ROS from apt needs none of it.
if(NOT DEFINED PYTHON_INCLUDE_DIRS)
  message(FATAL_ERROR "ros_wheels_python.cmake needs -DPYTHON_INCLUDE_DIRS=<Python's;numpy's>")
endif()

function(ros_wheels_python_includes)
  get_property(targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(target IN LISTS targets)
    get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
    if(dirs AND "${dirs}" MATCHES "/opt/python/")
      list(FILTER dirs EXCLUDE REGEX "^/opt/python/")
      list(APPEND dirs ${PYTHON_INCLUDE_DIRS})
      set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${dirs}")
    endif()
  endforeach()
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL ros_wheels_python_includes)
