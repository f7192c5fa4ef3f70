# PCD reader: PCL-based tools (writer, reference dump) and the LZF decoder check.
# They need only gdt_io and PCL; PCL headers are included as system headers
# (their warnings are not ours).
function(gdt_pcd_pcl_tool name)
  add_executable(${name} ${ARGN})
  target_include_directories(${name} SYSTEM PRIVATE ${PCL_INCLUDE_DIRS})
  target_compile_definitions(${name} PRIVATE ${PCL_DEFINITIONS})
  target_link_libraries(${name} PRIVATE gdt_io ${PCL_COMMON_LIBRARIES} ${PCL_IO_LIBRARIES})
  gdt_target_flags(${name})
endfunction()

gdt_pcd_pcl_tool(pcd_write_pcl ${CMAKE_CURRENT_SOURCE_DIR}/tools/pcd_write_pcl.cpp)
gdt_pcd_pcl_tool(pcd_dump_pcl ${CMAKE_CURRENT_SOURCE_DIR}/tools/pcd_dump_pcl.cpp
                 ${CMAKE_CURRENT_SOURCE_DIR}/tools/pcd_pcl.cpp)
gdt_pcd_pcl_tool(pcd_lzf_check ${CMAKE_CURRENT_SOURCE_DIR}/tools/pcd_lzf_check.cpp)
add_test(NAME pcd_lzf COMMAND pcd_lzf_check 300)
