/* layout.cl: reports sizeof and offsetof of the shared structs (psf_shared.h)
 * as the device compiler lays them out; tests/test_layout.cpp compares them with
 * the host's. Writes pairs (name id order fixed by the host test). */

#define PSF_OFFSET(type, field) ((uint)(size_t)&(((type*)0)->field))

__kernel void layout_report(__global uint* out) {
  if (get_global_id(0) != 0) return;
  uint i = 0;
  out[i++] = sizeof(Ray);
  out[i++] = PSF_OFFSET(Ray, dir);
  out[i++] = sizeof(Hit);
  out[i++] = PSF_OFFSET(Hit, prim);
  out[i++] = PSF_OFFSET(Hit, v);
  out[i++] = sizeof(BvhTriPack);
  out[i++] = PSF_OFFSET(BvhTriPack, e2_x);
  out[i++] = PSF_OFFSET(BvhTriPack, prim);
  out[i++] = sizeof(BvhNode);
  out[i++] = PSF_OFFSET(BvhNode, max_x);
  out[i++] = PSF_OFFSET(BvhNode, min_z);
  out[i++] = PSF_OFFSET(BvhNode, child);
  out[i++] = sizeof(Camera);
  out[i++] = PSF_OFFSET(Camera, down);
  out[i++] = PSF_OFFSET(Camera, width);
  out[i++] = PSF_OFFSET(Camera, focus);
  out[i++] = PSF_OFFSET(Camera, orthographic);
  out[i++] = PSF_OFFSET(Camera, filter_b);
  out[i++] = PSF_OFFSET(Camera, shift_t);
  out[i++] = sizeof(Material);
  out[i++] = PSF_OFFSET(Material, emission);
  out[i++] = PSF_OFFSET(Material, type);
  out[i++] = PSF_OFFSET(Material, two_sided);
  out[i++] = PSF_OFFSET(Material, specular);
  out[i++] = PSF_OFFSET(Material, k);
  out[i++] = PSF_OFFSET(Material, alpha_u);
  out[i++] = PSF_OFFSET(Material, flags);
  out[i++] = PSF_OFFSET(Material, tex_bump);
  out[i++] = PSF_OFFSET(Material, opacity);
  out[i++] = PSF_OFFSET(Material, tex_table);
  out[i++] = PSF_OFFSET(Material, tex_alpha);
  out[i++] = PSF_OFFSET(Material, tex_emission);
  out[i++] = PSF_OFFSET(Material, blend);
  out[i++] = PSF_OFFSET(Material, tex_blend);
  out[i++] = PSF_OFFSET(Material, interior);
  out[i++] = PSF_OFFSET(Material, interior_albedo);
  out[i++] = PSF_OFFSET(Material, exterior);
  out[i++] = sizeof(TextureInfo);
  out[i++] = PSF_OFFSET(TextureInfo, uv_v);
  out[i++] = PSF_OFFSET(TextureInfo, offset);
  out[i++] = PSF_OFFSET(TextureInfo, flags);
  out[i++] = sizeof(TriAttrib);
  out[i++] = PSF_OFFSET(TriAttrib, uv01);
  out[i++] = PSF_OFFSET(TriAttrib, u2);
  out[i++] = PSF_OFFSET(TriAttrib, flags);
  out[i++] = PSF_OFFSET(TriAttrib, color2);
  out[i++] = sizeof(Emitter);
  out[i++] = PSF_OFFSET(Emitter, radiance);
  out[i++] = PSF_OFFSET(Emitter, prim);
  out[i++] = PSF_OFFSET(Emitter, two_sided);
  out[i++] = PSF_OFFSET(Emitter, type);
  out[i++] = PSF_OFFSET(Emitter, tex_emission);
  out[i++] = sizeof(Environment);
  out[i++] = PSF_OFFSET(Environment, to_map2);
  out[i++] = PSF_OFFSET(Environment, scale);
  out[i++] = PSF_OFFSET(Environment, width);
  out[i++] = PSF_OFFSET(Environment, present);
  out[i++] = sizeof(PathState);
  out[i++] = PSF_OFFSET(PathState, radiance);
  out[i++] = PSF_OFFSET(PathState, prev_pos);
  out[i++] = PSF_OFFSET(PathState, pixel);
  out[i++] = PSF_OFFSET(PathState, flags);
  out[i++] = PSF_OFFSET(PathState, vertex_radiance);
  out[i++] = sizeof(PathVertex);
  out[i++] = PSF_OFFSET(PathVertex, normal);
  out[i++] = PSF_OFFSET(PathVertex, albedo);
  out[i++] = PSF_OFFSET(PathVertex, alpha);
  out[i++] = sizeof(FrameParams);
  out[i++] = PSF_OFFSET(FrameParams, max_depth);
  out[i++] = PSF_OFFSET(FrameParams, batch_size);
  out[i++] = PSF_OFFSET(FrameParams, rr_depth);
  out[i++] = PSF_OFFSET(FrameParams, first_sphere);
  out[i++] = PSF_OFFSET(FrameParams, camera_medium);
  out[i++] = PSF_OFFSET(FrameParams, max_rounds);
  out[i++] = sizeof(FilterParams);
  out[i++] = PSF_OFFSET(FilterParams, count);
  out[i++] = PSF_OFFSET(FilterParams, cells27);
  out[i++] = PSF_OFFSET(FilterParams, stretch);
}
