# Mesh structure, verifiers, CPU reference triangulator and flip engine.
set(GDT_MESH_GEN ${CMAKE_CURRENT_SOURCE_DIR}/c/gen_degenerate.c)

gdt_add_test_exe(test_mesh ${CMAKE_CURRENT_SOURCE_DIR}/c/test_mesh.c ${GDT_MESH_GEN})
add_test(NAME mesh_checkers COMMAND test_mesh)

gdt_add_test_exe(test_reference ${CMAKE_CURRENT_SOURCE_DIR}/c/test_reference.c ${GDT_MESH_GEN})
add_test(NAME mesh_reference COMMAND test_reference)
# Throughput and full verification on one million points; too slow under
# the sanitizers.
add_test(NAME mesh_reference_1m COMMAND test_reference --big 1000000)
set_tests_properties(mesh_reference_1m PROPERTIES LABELS nosanitize)

gdt_add_test_exe(test_flip ${CMAKE_CURRENT_SOURCE_DIR}/c/test_flip.c ${GDT_MESH_GEN})
add_test(NAME mesh_flip COMMAND test_flip)

# Reference triangulator as a command-line tool (tests/python/test_reference.py).
gdt_add_test_exe(ref_dt ${CMAKE_CURRENT_SOURCE_DIR}/tools/ref_dt.c)

# Comparison with CGAL's Delaunay triangulation on points in general position.
find_package(CGAL QUIET)
if(CGAL_FOUND)
  add_executable(cgal_dt ${CMAKE_CURRENT_SOURCE_DIR}/tools/cgal_dt.cpp)
  target_link_libraries(cgal_dt PRIVATE CGAL::CGAL)
  gdt_target_flags(cgal_dt)
  gdt_add_test_exe(test_reference_cgal ${CMAKE_CURRENT_SOURCE_DIR}/c/test_reference_cgal.c
                   ${GDT_MESH_GEN})
  add_test(NAME mesh_reference_cgal
           COMMAND test_reference_cgal $<TARGET_FILE:cgal_dt> ${CMAKE_CURRENT_BINARY_DIR})
else()
  message(STATUS "CGAL not found (Debian package libcgal-dev): the CGAL comparison test "
                 "mesh_reference_cgal is skipped")
endif()
