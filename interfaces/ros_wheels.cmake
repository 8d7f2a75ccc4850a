# What an interface package here needs to build under pip from ROS 2 Jazzy's PyPI wheels
# (each CMakeLists.txt beside this includes it after project()).

# Under pip, the ROS build tools are wheels in pip's isolated build environment: their CMake
# packages lie under that environment's root, four levels above the ament_package module.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)
execute_process(
  COMMAND "${Python3_EXECUTABLE}" -c
    "import ament_package, pathlib; print(pathlib.Path(ament_package.__file__).resolve().parents[4])"
  OUTPUT_VARIABLE ros_wheels_prefix OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE found)
if(found EQUAL 0)
  list(PREPEND CMAKE_PREFIX_PATH "${ros_wheels_prefix}")
  # The generators find the type supports through the ament index.
  set(ENV{AMENT_PREFIX_PATH} "${ros_wheels_prefix}:$ENV{AMENT_PREFIX_PATH}")
endif()

# mend_generator_py_targets(PACKAGE...): the PyPI wheels' CMake target files name the
# include directories of the machine they were built on; the Python generator's targets
# need this machine's Python and numpy. Call it once the packages are found.
function(mend_generator_py_targets)
  foreach(package ${ARGN})
    if(TARGET ${package}::${package}__rosidl_generator_py)
      set_target_properties(${package}::${package}__rosidl_generator_py PROPERTIES
        INTERFACE_INCLUDE_DIRECTORIES "${Python3_INCLUDE_DIRS};${Python3_NumPy_INCLUDE_DIRS}")
    endif()
  endforeach()
endfunction()
