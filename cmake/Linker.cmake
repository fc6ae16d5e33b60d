# The linker: LLVM's lld where the compiler can use it (clang and GCC both take -fuse-ld=lld), GNU
# ld otherwise. A fresh build links about a hundred programs (every test executable, the fuzz
# targets); under the sanitizers GNU ld took 97 s of CPU for them, a quarter of which is what
# scripts/test.sh spends waiting on links. lld comes from scripts/install-deps.sh; the output is
# the same program, only linked faster. MCSTAT_USE_LLD=OFF keeps the system's default linker.
include(CheckLinkerFlag)
option(MCSTAT_USE_LLD "Link with lld when the compiler accepts -fuse-ld=lld" ON)
if(MCSTAT_USE_LLD)
  check_linker_flag(CXX "-fuse-ld=lld" MCSTAT_HAVE_LLD)
  if(MCSTAT_HAVE_LLD)
    add_link_options(-fuse-ld=lld)
  endif()
endif()
