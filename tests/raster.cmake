# The DEM: the grid on the lattice, the rasteriser's ownership rule and
# values (core/gdt_raster.h), the streaming GeoTIFF writer's cache and
# spills (io/gdt_dem.h).  The end-to-end checks against an independent
# Python oracle and gdal_grid are tests/python/test_dem.py.
gdt_add_test_exe(test_raster ${CMAKE_CURRENT_SOURCE_DIR}/c/test_raster.c)
# it reads the GeoTIFFs back through GDAL itself
target_link_libraries(test_raster PRIVATE PkgConfig::GDAL)
add_test(NAME raster COMMAND test_raster ${CMAKE_CURRENT_BINARY_DIR}/raster-work)
# The half-lattice predicates against Python's big integers (test_dem.py).
gdt_add_test_exe(half_eval ${CMAKE_CURRENT_SOURCE_DIR}/tools/half_eval.c)
