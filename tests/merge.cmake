# The seam merge by rows: simulated tiles (reference triangulator,
# certification, seam extraction), merged round by round and all at once,
# compared with the triangulation of the whole point set.
gdt_add_test_exe(test_merge_stream ${CMAKE_CURRENT_SOURCE_DIR}/c/test_merge_stream.c)
add_test(NAME merge_stream COMMAND test_merge_stream)
gdt_add_test_exe(test_trim ${CMAKE_CURRENT_SOURCE_DIR}/c/test_trim.c)
add_test(NAME trim COMMAND test_trim)
