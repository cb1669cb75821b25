# The PyPI ROS 2 wheels export their Python type-support targets with the include directories of
# the machine that built them (/opt/python/<abi>/include/python3.X and its numpy headers), which
# do not exist here and stop CMake's generate step. Point every such missing directory of the
# imported targets at this Python's headers; directories that exist are left alone, so a ROS 2
# install from its own packages is unaffected.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)

function(use_local_python_includes)
  get_property(_targets DIRECTORY PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_fixed)
    foreach(_dir IN LISTS _dirs)
      if(NOT EXISTS "${_dir}" AND _dir MATCHES "/numpy/(_core/)?include$")
        set(_dir "${Python3_NumPy_INCLUDE_DIRS}")
      elseif(NOT EXISTS "${_dir}" AND _dir MATCHES "/include/python3\\.[0-9]+$")
        set(_dir "${Python3_INCLUDE_DIRS}")
      endif()
      list(APPEND _fixed "${_dir}")
    endforeach()
    set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_fixed}")
  endforeach()
endfunction()
