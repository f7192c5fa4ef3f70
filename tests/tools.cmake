# Test tools shared by several Python test files.
gdt_add_test_exe(gdt_dump ${CMAKE_CURRENT_SOURCE_DIR}/tools/gdt_dump.c)
gdt_add_test_exe(src_read ${CMAKE_CURRENT_SOURCE_DIR}/tools/src_read.c)
