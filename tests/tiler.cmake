# Out-of-core tiler: pass 1 (OpenVDB index), pass 2 (spill files), --dup
# merge, halos, the tiny test budget.  The Python suite
# (tests/python/test_tiler.py) drives tiler_run on generated LAS files and
# reads index.vdb back with tiler_vdb_dump, which uses OpenVDB's own API.
gdt_add_test_exe(tiler_run ${CMAKE_CURRENT_SOURCE_DIR}/tools/tiler_run.c)
gdt_add_test_exe(tiler_vdb_dump ${CMAKE_CURRENT_SOURCE_DIR}/tools/tiler_vdb_dump.cpp)
target_link_libraries(tiler_vdb_dump PRIVATE OpenVDB::openvdb)
gdt_add_test_exe(test_tiler ${CMAKE_CURRENT_SOURCE_DIR}/c/test_tiler.c)
add_test(NAME tiler COMMAND test_tiler ${CMAKE_CURRENT_BINARY_DIR}/tiler-work)

# Direct I/O of the tile files (tiled_files.c): lengths around the block
# size, read back in pieces of many sizes.
gdt_add_test_exe(test_tile_files ${CMAKE_CURRENT_SOURCE_DIR}/c/test_tile_files.c)
add_test(NAME tile_files COMMAND test_tile_files ${CMAKE_CURRENT_BINARY_DIR})
# How an MPI job shares its tiles: the tile stage's owners spread over tile
# order and balanced on every prefix; pass 2's contiguous shares.
gdt_add_test_exe(test_mpi_sched ${CMAKE_CURRENT_SOURCE_DIR}/c/test_mpi_sched.c)
add_test(NAME mpi_sched COMMAND test_mpi_sched)
# The parser of a .tri file's header and seam section: verdicts and
# message numbers of valid, foreign, overflowing and out-of-range files.
gdt_add_test_exe(test_tri_seam ${CMAKE_CURRENT_SOURCE_DIR}/c/test_tri_seam.c)
add_test(NAME tile_files_tri COMMAND test_tri_seam)

# The tile files' checksum and the input fingerprint hash see damage.
gdt_add_test_exe(test_hash ${CMAKE_CURRENT_SOURCE_DIR}/c/test_hash.c)
add_test(NAME hash COMMAND test_hash)
# The tiled run's DEM rasteriser: the same GeoTIFF bytes whether a tile's
# faces are rasterised by the caller alone or handed to helper threads, and
# a bad face reported in face order.
gdt_add_test_exe(test_tiled_dem ${CMAKE_CURRENT_SOURCE_DIR}/c/test_tiled_dem.c)
add_test(NAME tiled_dem COMMAND test_tiled_dem ${CMAKE_CURRENT_BINARY_DIR}/tiled-dem-work)
