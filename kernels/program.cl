/* program.cl: the whole kernel program, one file per pipeline stage.
 * The host builds this file with `-cl-std=CL1.2`; `#include "..."` lines are
 * expanded by the host from the sources embedded at build time. */
#include "psf_shared.h"
#include "layout.cl"
#include "sampling.cl"
#include "raycast.cl"
#include "camera.cl"
#include "bsdf.cl"
#include "emitter.cl"
#include "shade.cl"
#include "accumulate.cl"
