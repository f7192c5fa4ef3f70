# Test tools shared by several Python test files.
gdt_add_test_exe(gdt_dump ${CMAKE_CURRENT_SOURCE_DIR}/tools/gdt_dump.c)
gdt_add_test_exe(src_read ${CMAKE_CURRENT_SOURCE_DIR}/tools/src_read.c)
# LD_PRELOAD shim that makes pthread_create fail after a given number of calls.
add_library(gdt_fail_threads MODULE ${CMAKE_CURRENT_SOURCE_DIR}/tools/fail_threads.c)
target_link_libraries(gdt_fail_threads PRIVATE ${CMAKE_DL_LIBS})
gdt_target_flags(gdt_fail_threads)
# LD_PRELOAD shim that makes positional writes to matching files fail (ENOSPC).
add_library(gdt_fail_write MODULE ${CMAKE_CURRENT_SOURCE_DIR}/tools/fail_write.c)
target_link_libraries(gdt_fail_write PRIVATE ${CMAKE_DL_LIBS})
gdt_target_flags(gdt_fail_write)
# LD_PRELOAD shim that makes opening matching files fail (EIO), in one kind of thread.
add_library(gdt_fail_open MODULE ${CMAKE_CURRENT_SOURCE_DIR}/tools/fail_open.c)
target_link_libraries(gdt_fail_open PRIVATE ${CMAKE_DL_LIBS} Threads::Threads)
gdt_target_flags(gdt_fail_open)
# LD_PRELOAD shim that reports environment changes off the main thread.
add_library(gdt_env_guard MODULE ${CMAKE_CURRENT_SOURCE_DIR}/tools/env_guard.c)
target_link_libraries(gdt_env_guard PRIVATE ${CMAKE_DL_LIBS})
gdt_target_flags(gdt_env_guard)
# The tiled run's stages over a subset of the tiles (tests/python/test_stages.py).
gdt_add_test_exe(stages_subset ${CMAKE_CURRENT_SOURCE_DIR}/tools/stages_subset.c)
