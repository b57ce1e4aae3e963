// The shared structs (kernels/psf_shared.h) have the same layout on the device as on the host.
#include <catch2/catch.hpp>
#include <cstddef>

#include "psf_shared.h"
#include "support.h"

TEST_CASE("Layout: shared structs match between host and device", "[layout]") {
  // Same order as kernels/layout.cl.
  const std::vector<std::pair<const char*, size_t>> host = {
      {"sizeof(Ray)", sizeof(Ray)},
      {"offsetof(Ray, dir)", offsetof(Ray, dir)},
      {"sizeof(Hit)", sizeof(Hit)},
      {"offsetof(Hit, prim)", offsetof(Hit, prim)},
      {"offsetof(Hit, v)", offsetof(Hit, v)},
      {"sizeof(BvhTriPack)", sizeof(BvhTriPack)},
      {"offsetof(BvhTriPack, e2_x)", offsetof(BvhTriPack, e2_x)},
      {"offsetof(BvhTriPack, prim)", offsetof(BvhTriPack, prim)},
      {"sizeof(BvhNode)", sizeof(BvhNode)},
      {"offsetof(BvhNode, max_x)", offsetof(BvhNode, max_x)},
      {"offsetof(BvhNode, min_z)", offsetof(BvhNode, min_z)},
      {"offsetof(BvhNode, child)", offsetof(BvhNode, child)},
      {"sizeof(Camera)", sizeof(Camera)},
      {"offsetof(Camera, down)", offsetof(Camera, down)},
      {"offsetof(Camera, width)", offsetof(Camera, width)},
      {"offsetof(Camera, focus)", offsetof(Camera, focus)},
      {"offsetof(Camera, orthographic)", offsetof(Camera, orthographic)},
      {"offsetof(Camera, filter_b)", offsetof(Camera, filter_b)},
      {"offsetof(Camera, shift_t)", offsetof(Camera, shift_t)},
      {"sizeof(Material)", sizeof(Material)},
      {"offsetof(Material, emission)", offsetof(Material, emission)},
      {"offsetof(Material, type)", offsetof(Material, type)},
      {"offsetof(Material, two_sided)", offsetof(Material, two_sided)},
      {"offsetof(Material, specular)", offsetof(Material, specular)},
      {"offsetof(Material, k)", offsetof(Material, k)},
      {"offsetof(Material, alpha_u)", offsetof(Material, alpha_u)},
      {"offsetof(Material, flags)", offsetof(Material, flags)},
      {"offsetof(Material, tex_bump)", offsetof(Material, tex_bump)},
      {"offsetof(Material, opacity)", offsetof(Material, opacity)},
      {"offsetof(Material, tex_table)", offsetof(Material, tex_table)},
      {"offsetof(Material, tex_alpha)", offsetof(Material, tex_alpha)},
      {"offsetof(Material, tex_emission)", offsetof(Material, tex_emission)},
      {"offsetof(Material, blend)", offsetof(Material, blend)},
      {"offsetof(Material, tex_blend)", offsetof(Material, tex_blend)},
      {"offsetof(Material, interior)", offsetof(Material, interior)},
      {"offsetof(Material, interior_albedo)", offsetof(Material, interior_albedo)},
      {"offsetof(Material, exterior)", offsetof(Material, exterior)},
      {"sizeof(TextureInfo)", sizeof(TextureInfo)},
      {"offsetof(TextureInfo, uv_v)", offsetof(TextureInfo, uv_v)},
      {"offsetof(TextureInfo, offset)", offsetof(TextureInfo, offset)},
      {"offsetof(TextureInfo, flags)", offsetof(TextureInfo, flags)},
      {"sizeof(TriAttrib)", sizeof(TriAttrib)},
      {"offsetof(TriAttrib, uv01)", offsetof(TriAttrib, uv01)},
      {"offsetof(TriAttrib, u2)", offsetof(TriAttrib, u2)},
      {"offsetof(TriAttrib, flags)", offsetof(TriAttrib, flags)},
      {"offsetof(TriAttrib, color2)", offsetof(TriAttrib, color2)},
      {"sizeof(Emitter)", sizeof(Emitter)},
      {"offsetof(Emitter, radiance)", offsetof(Emitter, radiance)},
      {"offsetof(Emitter, prim)", offsetof(Emitter, prim)},
      {"offsetof(Emitter, two_sided)", offsetof(Emitter, two_sided)},
      {"offsetof(Emitter, type)", offsetof(Emitter, type)},
      {"offsetof(Emitter, tex_emission)", offsetof(Emitter, tex_emission)},
      {"sizeof(Environment)", sizeof(Environment)},
      {"offsetof(Environment, to_map2)", offsetof(Environment, to_map2)},
      {"offsetof(Environment, scale)", offsetof(Environment, scale)},
      {"offsetof(Environment, width)", offsetof(Environment, width)},
      {"offsetof(Environment, present)", offsetof(Environment, present)},
      {"sizeof(PathState)", sizeof(PathState)},
      {"offsetof(PathState, radiance)", offsetof(PathState, radiance)},
      {"offsetof(PathState, prev_pos)", offsetof(PathState, prev_pos)},
      {"offsetof(PathState, pixel)", offsetof(PathState, pixel)},
      {"offsetof(PathState, flags)", offsetof(PathState, flags)},
      {"offsetof(PathState, vertex_radiance)", offsetof(PathState, vertex_radiance)},
      {"sizeof(PathVertex)", sizeof(PathVertex)},
      {"offsetof(PathVertex, normal)", offsetof(PathVertex, normal)},
      {"offsetof(PathVertex, albedo)", offsetof(PathVertex, albedo)},
      {"offsetof(PathVertex, alpha)", offsetof(PathVertex, alpha)},
      {"sizeof(FrameParams)", sizeof(FrameParams)},
      {"offsetof(FrameParams, max_depth)", offsetof(FrameParams, max_depth)},
      {"offsetof(FrameParams, batch_size)", offsetof(FrameParams, batch_size)},
      {"offsetof(FrameParams, rr_depth)", offsetof(FrameParams, rr_depth)},
      {"offsetof(FrameParams, first_sphere)", offsetof(FrameParams, first_sphere)},
      {"offsetof(FrameParams, camera_medium)", offsetof(FrameParams, camera_medium)},
      {"offsetof(FrameParams, max_rounds)", offsetof(FrameParams, max_rounds)},
      {"offsetof(FrameParams, spheres)", offsetof(FrameParams, spheres)},
      {"offsetof(FrameParams, flat_packs)", offsetof(FrameParams, flat_packs)},
      {"sizeof(FilterParams)", sizeof(FilterParams)},
      {"offsetof(FilterParams, count)", offsetof(FilterParams, count)},
      {"offsetof(FilterParams, cells27)", offsetof(FilterParams, cells27)},
      {"offsetof(FilterParams, stretch)", offsetof(FilterParams, stretch)},
      {"offsetof(FilterParams, demodulate)", offsetof(FilterParams, demodulate)},
  };
  auto& rt = psf::test::runtime();
  cl::Buffer out = rt.buffer(CL_MEM_WRITE_ONLY, 128 * sizeof(cl_uint));
  rt.launch("layout_report", 1, 1, out);
  REQUIRE(host.size() <= 128);  // the buffer's size, here and in test_runtime
  auto device = rt.download<cl_uint>(out, host.size());
  for (size_t i = 0; i < host.size(); ++i) {
    INFO(host[i].first);
    CHECK(device[i] == host[i].second);
  }
  // Every buffer struct is a multiple of 16 bytes so arrays of it stay float4-aligned.
  for (size_t s : {sizeof(Ray), sizeof(Hit), sizeof(BvhTriPack), sizeof(BvhNode), sizeof(Camera),
                   sizeof(Material), sizeof(TextureInfo), sizeof(TriAttrib), sizeof(Emitter), sizeof(Environment), sizeof(PathState), sizeof(PathVertex),
                   sizeof(FrameParams), sizeof(FilterParams)})
    CHECK(s % 16 == 0);
}
