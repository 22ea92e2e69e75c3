# Passed to CMake as -DCMAKE_PROJECT_INCLUDE=... when the workspace builds tf2_msgs against the
# ROS 2 Jazzy wheels from the package registry.
#
# Why: those wheels were built in a manylinux image, and the CMake files they export (for
# example geometry_msgs' `export_geometry_msgs__rosidl_generator_pyExport.cmake`) name that
# image's Python and NumPy header folders, /opt/python/cp311-cp311/include/python3.11 and
# .../site-packages/numpy/_core/include, which do not exist here. CMake refuses an imported
# target whose INTERFACE_INCLUDE_DIRECTORIES names a missing folder, so the Python type
# support of tf2_msgs would not configure.
#
# What: at the end of configuring the directory (a deferred call, after every find_package has
# imported its targets), rewrite those folders in the imported targets to this interpreter's
# Python and NumPy include folders. No installed file is edited; on a full ROS 2 install the
# exported paths exist, nothing matches and this file changes nothing.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development.Module NumPy)

function(_vbn_rewrite_manylinux_include_dirs)
  get_property(_targets DIRECTORY PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs OR NOT _dirs MATCHES "/opt/python/")
      continue()
    endif()
    set(_fixed "")
    foreach(_dir IN LISTS _dirs)
      if(_dir MATCHES "^/opt/python/[^/]+/include/python")
        list(APPEND _fixed ${Python3_INCLUDE_DIRS})
      elseif(_dir MATCHES "^/opt/python/.*/numpy/_core/include$")
        list(APPEND _fixed ${Python3_NumPy_INCLUDE_DIRS})
      else()
        list(APPEND _fixed "${_dir}")
      endif()
    endforeach()
    list(REMOVE_DUPLICATES _fixed)
    set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_fixed}")
  endforeach()
endfunction()

cmake_language(DEFER CALL _vbn_rewrite_manylinux_include_dirs)
