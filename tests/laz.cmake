# LAZ decoder: the arithmetic decoder and the version 1 RGB12 and BYTE codings
# against a test-side encoder (tests/c/laz_test_enc.h; bounds
# included); the Python suite (tests/python/test_laz_decode.py) compares
# laz_decode with laspy's lazrs and laszip back-ends.
gdt_add_test_exe(test_laz_arith ${CMAKE_CURRENT_SOURCE_DIR}/c/test_laz_arith.c)
add_test(NAME laz_arith COMMAND test_laz_arith)
gdt_add_test_exe(laz_decode ${CMAKE_CURRENT_SOURCE_DIR}/tools/laz_decode.c)
gdt_add_test_exe(test_laz_v1 ${CMAKE_CURRENT_SOURCE_DIR}/c/test_laz_v1.c)
add_test(NAME laz_v1 COMMAND test_laz_v1)
