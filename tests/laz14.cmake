# Layered LAZ chunks (formats 6-10): the decoder's contracts on hand-made
# chunks; tests/python/test_laz14_decode.py compares its decoding of real
# streams with laspy's LASzip and laz-rs writers.
gdt_add_test_exe(test_laz14 ${CMAKE_CURRENT_SOURCE_DIR}/c/test_laz14.c)
add_test(NAME laz14 COMMAND test_laz14)
