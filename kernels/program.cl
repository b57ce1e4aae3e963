/* program.cl: the whole kernel program, one file per pipeline stage.
 * The host builds this file with `-cl-std=CL1.2`; `#include "..."` lines are
 * expanded by the host from the sources embedded at build time. */
#include "psf_shared.h"

/* A hint to fetch the cache line at global address p for a work-item further
 * on. Kernels that read at random, one line per work-item, wait on memory in
 * each work-item in turn where PoCL runs them as a loop; a prefetch issued
 * PSF_PREFETCH_AHEAD work-items earlier overlaps those waits (the environment's
 * sampling kernels, shade and shade_shadows in shade.cl, gather_tuples and
 * scatter_values in tuples.cl; the latter's writes with psf_prefetch_write). PSF_PREFETCH (set
 * by the host for CPU devices): Clang's __builtin_prefetch, since OpenCL's
 * prefetch() is empty on PoCL; elsewhere nothing. */
#ifndef PSF_PREFETCH
#define PSF_PREFETCH 0
#endif
#define PSF_PREFETCH_AHEAD 16u
#if PSF_PREFETCH
#define psf_prefetch(p) __builtin_prefetch((p), 0, 3)
#define psf_prefetch_write(p) __builtin_prefetch((p), 1, 3)
#else
#define psf_prefetch(p) ((void)0)
#define psf_prefetch_write(p) ((void)0)
#endif

/* PSF_CPU_DEVICE (set by the host for CPU devices): where a function is better
 * out of line on a CPU and inlined on a GPU (raycast.cl's sphere test). */
#ifndef PSF_CPU_DEVICE
#define PSF_CPU_DEVICE 0
#endif

/* Forced inlining: raycast.cl's traversal (a call would keep the hit record in
 * memory), shade.cl's bounce, emitter.cl's light sample, filter.cl's queries.
 * PSF_NO_FORCE_INLINE (scripts/oclgrind) turns it off: inlining emits LLVM
 * intrinsics Oclgrind 21.10 cannot execute (llvm.experimental.noalias.scope.decl
 * for the structs passed by value). */
#ifdef PSF_NO_FORCE_INLINE
#define PSF_FORCE_INLINE inline
#else
#define PSF_FORCE_INLINE inline __attribute__((always_inline))
#endif

/* Bit k set where lane k of a comparison result (-1 or 0 per lane) is true.
 * Where the target has AVX (PoCL on x86) the lanes' sign bits in one
 * instruction (vmovmskps; bench_raycast's paired ratios to Embree 5 % higher
 * than with the multiplication), elsewhere one byte per lane gathered into
 * the top byte by a multiplication (PSF_PORTABLE_LANES=1 asks for it on AVX
 * targets too: a test builds the GPUs' program on PoCL so). */
#ifndef PSF_PORTABLE_LANES
#define PSF_PORTABLE_LANES 0
#endif
inline uint psf_lanes8(int8 c) {
#if defined(__AVX__) && !PSF_PORTABLE_LANES
  return (uint)__builtin_ia32_movmskps256(as_float8(c));
#else
  const ulong bytes = as_ulong(convert_uchar8(c) & (uchar8)(1));
  return (uint)((bytes * 0x0102040810204080ul) >> 56);
#endif
}

#include "layout.cl"
#include "sampling.cl"
#include "texture.cl"
#include "raycast.cl"
#include "camera.cl"
#include "bsdf.cl"
#include "surface.cl"
#include "bsdf_test.cl"
#include "emitter.cl"
#include "shade.cl"
#include "trace_lanes.cl"
#include "emission.cl"
#include "visibility.cl"
#include "cell_keys.cl"
#include "tuples.cl"
#include "sort.cl"
#include "cell_ranges.cl"
#include "filter.cl"
#include "filter_test.cl"
#include "accumulate.cl"
