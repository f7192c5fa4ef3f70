# LAS reader: CRS interpretation unit test and a streaming test with many
# buffer/chunk sizes.  The Python suite (tests/python/test_las_reader.py)
# compares gdt_dump with laspy on real and generated files.
gdt_add_test_exe(test_las_crs ${CMAKE_CURRENT_SOURCE_DIR}/c/test_las_crs.c)
add_test(NAME las_crs COMMAND test_las_crs)
gdt_add_test_exe(test_las_stream ${CMAKE_CURRENT_SOURCE_DIR}/c/test_las_stream.c)
add_test(NAME las_stream COMMAND test_las_stream ${CMAKE_CURRENT_BINARY_DIR})
gdt_add_test_exe(test_las_copy ${CMAKE_CURRENT_SOURCE_DIR}/c/test_las_copy.c)
add_test(NAME las_copy COMMAND test_las_copy ${CMAKE_CURRENT_BINARY_DIR})
