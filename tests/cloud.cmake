# Cloud, lattice, duplicate merge and out-of-core duplicate count.
# The Python suite (tests/python/test_cloud.py) drives cloud_dump on real and
# laspy-generated files.
gdt_add_test_exe(cloud_dump ${CMAKE_CURRENT_SOURCE_DIR}/tools/cloud_dump.c)
gdt_add_test_exe(test_cloud_lattice ${CMAKE_CURRENT_SOURCE_DIR}/c/test_cloud_lattice.c)
add_test(NAME cloud_lattice COMMAND test_cloud_lattice)
gdt_add_test_exe(test_dedup ${CMAKE_CURRENT_SOURCE_DIR}/c/test_dedup.c)
add_test(NAME dedup COMMAND test_dedup)
gdt_add_test_exe(test_dedup_count ${CMAKE_CURRENT_SOURCE_DIR}/c/test_dedup_count.c)
add_test(NAME dedup_count COMMAND test_dedup_count ${CMAKE_CURRENT_BINARY_DIR})
gdt_add_test_exe(test_cloud_stream ${CMAKE_CURRENT_SOURCE_DIR}/c/test_cloud_stream.c)
add_test(NAME cloud_stream COMMAND test_cloud_stream ${CMAKE_CURRENT_BINARY_DIR})
gdt_add_test_exe(test_replay ${CMAKE_CURRENT_SOURCE_DIR}/c/test_replay.c)
add_test(NAME replay COMMAND test_replay ${CMAKE_CURRENT_BINARY_DIR})
