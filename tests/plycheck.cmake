# Streaming exact checker of output PLYs: C unit test, and the command-line
# tool used by tests/python/test_plycheck.py.
gdt_add_test_exe(test_plycheck ${CMAKE_CURRENT_SOURCE_DIR}/c/test_plycheck.c
                 ${CMAKE_CURRENT_SOURCE_DIR}/c/gen_degenerate.c)
add_test(NAME plycheck_unit COMMAND test_plycheck ${CMAKE_CURRENT_BINARY_DIR})
gdt_add_test_exe(plycheck_run ${CMAKE_CURRENT_SOURCE_DIR}/tools/plycheck_run.c)
