# PLY writer: C unit test and the writer tool used by tests/python/test_ply_writer.py.
gdt_add_test_exe(ply_write ${CMAKE_CURRENT_SOURCE_DIR}/tools/ply_write.c)
gdt_add_test_exe(test_ply ${CMAKE_CURRENT_SOURCE_DIR}/c/test_ply.c)
add_test(NAME ply_unit COMMAND test_ply ${CMAKE_CURRENT_BINARY_DIR})
target_compile_definitions(test_ply PRIVATE GDT_TEST_VERSION="${PROJECT_VERSION}")
