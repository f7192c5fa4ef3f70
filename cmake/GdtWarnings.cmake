# Compiler flags shared by every target of the project.
# Exactness rule: no fast-math, no floating-point contraction anywhere.
set(GDT_C_FLAGS -Wall -Wextra -Wshadow -Wstrict-prototypes -Wmissing-prototypes
    -Wpointer-arith -Wformat=2 -ffp-contract=off -fno-fast-math)
set(GDT_CXX_FLAGS -Wall -Wextra -ffp-contract=off -fno-fast-math)
if(GDT_WERROR)
  list(APPEND GDT_C_FLAGS -Werror)
  list(APPEND GDT_CXX_FLAGS -Werror)
endif()

if(GDT_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endif()

# gdt_target_flags(target): apply the project's warning set to a target.
function(gdt_target_flags tgt)
  target_compile_options(${tgt} PRIVATE
    $<$<COMPILE_LANGUAGE:C>:${GDT_C_FLAGS}>
    $<$<COMPILE_LANGUAGE:CXX>:${GDT_CXX_FLAGS}>)
  target_compile_definitions(${tgt} PRIVATE _POSIX_C_SOURCE=200809L _FILE_OFFSET_BITS=64)
endfunction()
