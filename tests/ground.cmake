# The ground filter (--ground pmf): the whole-cloud oracle of the tiled
# run, driven by tests/python/test_ground.py.
gdt_add_test_exe(pmf_whole ${CMAKE_CURRENT_SOURCE_DIR}/tools/pmf_whole.c)
