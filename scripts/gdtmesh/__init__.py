"""Shared helpers of the gdt-tile mesh scripts.

Modules:
  ply        -- reading the output mesh (binary little-endian PLY) through numpy.memmap
                and recovering the exact lattice integers of its vertices
  exact      -- exact orient2d / incircle / tie-break signs on int64 arrays
                (float filter, wrap-around int64 and Python-int exact paths)
  spill      -- records distributed over hash buckets, in memory or in temp files
  cloudio    -- point-cloud I/O: a minimal LAS 1.2 writer, PCD and XYZ writers,
                LAS (laspy) and PCD readers that yield lattice integers in chunks
  degenerate -- seeded generators of degenerate point sets
  validate   -- the exact mesh checker behind scripts/validate_mesh.py
  compare    -- canonical triangle-set comparison behind scripts/compare_meshes.py
"""
