# Fuzz targets (tests/fuzz/): one per reader of untrusted bytes.
#   fuzz_las       LAS reader (gdt_source.h)
#   fuzz_lazfile   LAZ files through the LAS reader (gdt_source.h: LASzip
#                  point data, 0 to 3 decoder threads)
#   fuzz_pcd       PCD reader (gdt_source.h)
#   fuzz_plycheck  the PLY checker's reader (gdt_plycheck.h)
#   fuzz_job       the job-state loader (tiler/private/job.h)
#   fuzz_tri       the tile-file (.tri) seam parser (tiler/private/tiled_files.h)
#   fuzz_laz       the LASzip VLR parser and chunk decoder (io/private/laz_chunk.h)
#   fuzz_laz14     the layered (formats 6-10) chunk decoder (io/private/laz14.h)
# With GDT_FUZZ=ON (clang) each is a libFuzzer binary; scripts/fuzz.sh
# builds the seed corpora and runs them (smoke run, long campaign).  In
# every build, the saved inputs tests/fuzz/regress/<target>/ (inputs that
# once crashed a target, and hand-made hostile ones) are
# replayed as the test fuzz_regress_<target>: through libFuzzer in the fuzz
# build, through a plain main() (replay_main.c) otherwise, so they also run
# under the ASan build.
set(GDT_FUZZ_DIR ${CMAKE_CURRENT_SOURCE_DIR}/fuzz)
# gdt_fuzz_all: every fuzz target, for a fuzz tree that builds only what
# the fuzz runs need (with gdt-tile and pcd_write_pcl, which make the seeds)
add_custom_target(gdt_fuzz_all)

# gdt_fuzz_target(name SOURCES file... [DEFINES def...])
function(gdt_fuzz_target name)
  cmake_parse_arguments(F "" "" "SOURCES;DEFINES" ${ARGN})
  set(srcs ${F_SOURCES} ${GDT_FUZZ_DIR}/fuzz_input.c)
  if(GDT_FUZZ)
    set(exe fuzz_${name})
    add_executable(${exe} ${srcs})
    target_link_options(${exe} PRIVATE -fsanitize=fuzzer)
    # -runs=0 with folders: every saved input once, no mutation.
    set(cmd ${exe} -runs=0 ${GDT_FUZZ_DIR}/regress/${name})
  else()
    set(exe fuzz_${name}_replay)
    add_executable(${exe} ${srcs} ${GDT_FUZZ_DIR}/replay_main.c)
    set(cmd ${exe} ${GDT_FUZZ_DIR}/regress/${name})
  endif()
  target_link_libraries(${exe} PRIVATE gdt_tiler gdt_merge gdt_core gdt_io)
  target_include_directories(${exe} PRIVATE ${GDT_FUZZ_DIR})
  target_compile_definitions(${exe} PRIVATE ${F_DEFINES})
  gdt_target_flags(${exe})
  add_dependencies(gdt_fuzz_all ${exe})
  add_test(NAME fuzz_regress_${name} COMMAND ${cmd})
  set_tests_properties(fuzz_regress_${name} PROPERTIES LABELS "fuzz")
endfunction()

gdt_fuzz_target(las SOURCES ${GDT_FUZZ_DIR}/fuzz_source.c DEFINES GDT_FUZZ_FORMAT=1)
gdt_fuzz_target(lazfile SOURCES ${GDT_FUZZ_DIR}/fuzz_source.c DEFINES GDT_FUZZ_FORMAT=1
  GDT_FUZZ_LAZ=1)
gdt_fuzz_target(pcd SOURCES ${GDT_FUZZ_DIR}/fuzz_source.c DEFINES GDT_FUZZ_FORMAT=2)
gdt_fuzz_target(plycheck SOURCES ${GDT_FUZZ_DIR}/fuzz_plycheck.c)
gdt_fuzz_target(job SOURCES ${GDT_FUZZ_DIR}/fuzz_job.c)
gdt_fuzz_target(tri SOURCES ${GDT_FUZZ_DIR}/fuzz_tri.c)
gdt_fuzz_target(laz SOURCES ${GDT_FUZZ_DIR}/fuzz_laz.c)
gdt_fuzz_target(laz14 SOURCES ${GDT_FUZZ_DIR}/fuzz_laz14.c)
