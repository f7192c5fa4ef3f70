# Mesh writer (OBJ, LandXML, the PLY through the same interface): C unit test.
gdt_add_test_exe(test_mesh_out ${CMAKE_CURRENT_SOURCE_DIR}/c/test_mesh_out.c)
add_test(NAME mesh_out_unit COMMAND test_mesh_out ${CMAKE_CURRENT_BINARY_DIR})
target_compile_definitions(test_mesh_out PRIVATE GDT_TEST_VERSION="${PROJECT_VERSION}")
