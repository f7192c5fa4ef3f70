"""Synthetic LAS point clouds for testing and benchmarking gdt-tile.

The package writes LAS 1.1-1.4 files (point formats 0-10) with its own header
and VLR writer, streaming the points in bounded chunks.  Every point is a pure
function of the seed, the parameters and the point's (or laser pulse's) index,
so a file's bytes do not depend on the chunk size used to write it.

Modules:
  rng      counter-based hashing: per-index random bits, scalar layout streams
  terrain  smooth analytic ground surface
  lidar    airborne scan strips with voids, clusters, multiple returns, DEM patches
  simple   grid, uniform, rotated-grid (DEM) sections
  las      record layouts, header/VLR encoding, the streaming writer
  cloud    assembling sections into one cloud from command-line parameters
"""
