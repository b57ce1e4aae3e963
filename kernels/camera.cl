/* camera.cl: camera ray generation, the first stage of every batch.
 *
 * Path j of a batch has the global index g = first_path + j; it belongs to pixel
 * g mod (width * height) and is that pixel's sample number g div (width * height),
 * so a path gets the same samples whatever batch, device or work-group size
 * computes it. Sobol dimensions 0 and 1 place it around the pixel's centre, drawn
 * from the pixel filter (pixel_filter_offset).
 * Writes: the path's state, an empty filtering vertex, its camera ray (pinhole,
 * thin lens or orthographic, psf_shared.h Camera; Sobol dimensions 2 and 3 place it on the lens)
 * and its index into the first queue of live paths. */

inline ulong frame_first_path(FrameParams p) { return ((ulong)p.first_path_hi << 32) | (ulong)p.first_path_lo; }

/* The inverse error function in single precision (Giles, "Approximating the
 * erfinv function", GPU Computing Gems, 2011), for |x| < 1: both of its
 * polynomials, then the select, so that one body serves a float and a float8
 * (trace_lanes.cl's camera rays). */
#define PSF_DEFINE_ERFINV(T, SUFFIX)                  \
  inline T psf_erfinv##SUFFIX(T x) {                  \
    const T w0 = -log((1.0f - x) * (1.0f + x));       \
    T w = w0 - 2.5f, p = (T)(2.81022636e-08f);        \
    p = 3.43273939e-07f + p * w;                      \
    p = -3.5233877e-06f + p * w;                      \
    p = -4.39150654e-06f + p * w;                     \
    p = 0.00021858087f + p * w;                       \
    p = -0.00125372503f + p * w;                      \
    p = -0.00417768164f + p * w;                      \
    p = 0.246640727f + p * w;                         \
    p = 1.50140941f + p * w;                          \
    T v = sqrt(w0) - 3.0f, q = (T)(-0.000200214257f); \
    q = 0.000100950558f + q * v;                      \
    q = 0.00134934322f + q * v;                       \
    q = -0.00367342844f + q * v;                      \
    q = 0.00573950773f + q * v;                       \
    q = -0.0076224613f + q * v;                       \
    q = 0.00943887047f + q * v;                       \
    q = 1.00167406f + q * v;                          \
    q = 2.83297682f + q * v;                          \
    return select(q, p, w0 < 5.0f) * x;               \
  }

PSF_DEFINE_ERFINV(float, )
PSF_DEFINE_ERFINV(float8, 8)

/* A sample's offset from its pixel's centre along one axis, in pixels, from
 * the uniform number u by inverting the pixel filter's cdf: every sample then
 * has weight 1 and the pixel's mean is the image convolved with the filter
 * (filter importance sampling, as pbrt-v4 and, for these positive filters, the
 * same expectation as Mitsuba's weighted splatting). Box: uniform over the
 * half-width; tent of radius r: the triangle's cdf inverted; Gaussian: cut off
 * at its radius, erfinv of a uniform value of erf between the cut-offs. */
inline float pixel_filter_offset(Camera c, float u) {
  if (c.filter == PSF_PIXEL_FILTER_TENT)
    return u < 0.5f ? c.filter_a * (sqrt(2.0f * u) - 1.0f) : c.filter_a * (1.0f - sqrt(2.0f - 2.0f * u));
  if (c.filter == PSF_PIXEL_FILTER_GAUSSIAN) return c.filter_a * psf_erfinv((2.0f * u - 1.0f) * c.filter_b);
  return (2.0f * u - 1.0f) * (c.filter_a > 0.0f ? c.filter_a : 0.5f);
}

/* A path's place on the film: its pixel in the batch's image, that pixel's
 * sample number, and the film pixel's coordinates (the image's pixel offset by
 * its crop window's corner). A pixel's samples are keyed by its place in the
 * film, so that a crop window renders the film's pixels as a render of the whole
 * film does. */
inline uint camera_film_pixel(FrameParams params, Camera camera, uint j, uint* sample, uint* fx, uint* fy) {
  ulong pixels = (ulong)params.width * (ulong)params.height;
  ulong g = frame_first_path(params) + (ulong)j;
  uint pixel = (uint)(g % pixels);
  *sample = (uint)(g / pixels);
  *fx = pixel % params.width + (uint)camera.right.w;
  *fy = pixel / params.width + (uint)camera.down.w;
  return *fy * camera.width + *fx;
}

/* The camera ray through film pixel (fx, fy) for the sample's dimensions u8
 * (PSF_DIM_PIXEL on): s0, s1 place it around the pixel's centre, s2, s3 on the
 * lens. */
inline Ray camera_ray(Camera camera, uint fx, uint fy, float8 u8) {
#if PSF_DIM_LENS != PSF_DIM_PIXEL + 2
#error "the lens dimensions are read as u8.s2 and u8.s3"
#endif
  float u = u8.s0, v = u8.s1;
  float s = ((float)fx + 0.5f + pixel_filter_offset(camera, u)) / (float)camera.width + camera.shift_s;
  float t = ((float)fy + 0.5f + pixel_filter_offset(camera, v)) / (float)camera.height + camera.shift_t;
  float3 dir = camera.forward.xyz + (2.0f * s - 1.0f) * camera.right.xyz + (2.0f * t - 1.0f) * camera.down.xyz;
  float3 org = camera.origin.xyz;
  if (camera.orthographic) { /* parallel rays from the film's point */
    org += dir - camera.forward.xyz;
    dir = camera.forward.xyz;
  } else if (camera.aperture > 0.0f) {
    /* A thin lens: a point of the lens disk (uniform by area), aimed at where
     * the pinhole ray meets the plane in focus (dir has forward component 1). */
    float r = camera.aperture * sqrt(u8.s2); /* PSF_DIM_LENS */
    float c, sn = psf_sincos(2.0f * 3.14159265358979f * u8.s3, &c);
    float3 lens = r * (c * normalize(camera.right.xyz) + sn * normalize(camera.down.xyz));
    dir = camera.focus * dir - lens;
    org += lens;
  }
  /* The near and far clip planes, perpendicular to forward (Mitsuba's near_clip, far_clip). */
  float3 d = normalize(dir);
  float inv_cos = 1.0f / dot(d, camera.forward.xyz);
  Ray r;
  r.org = (float4)(org, camera.origin.w * inv_cos);
  r.dir = (float4)(d, camera.forward.w * inv_cos);
  return r;
}

__kernel void camera_rays(FrameParams params, Camera camera, __global const uint* sobol, __global PathState* states,
                          __global PathVertex* vertices, __global Ray* rays, __global uint* queue) {
  uint j = get_global_id(0);
  if (j >= params.batch_size) return;
  uint sample, fx, fy;
  uint film_pixel = camera_film_pixel(params, camera, j, &sample, &fx, &fy);
  /* Dimensions 0-7 drawn together (one pass over the sample index's bits,
   * sampling.cl): the pixel's two, and the lens's. */
  const float8 u8 = sample_8d_keyed(sobol, pixel_seed(params.seed, film_pixel), sample, PSF_DIM_PIXEL);
  Ray r = camera_ray(camera, fx, fy, u8);
  float3 org = r.org.xyz;
  rays[j] = r;
  queue[j] = j;
  PathState st;
  st.throughput = (float4)(1.0f, 1.0f, 1.0f, 0.0f);
  st.radiance = (float4)(0.0f);
  st.vertex_radiance = (float4)(0.0f);
  st.pending = (float4)(0.0f);
  st.prev_pos = (float4)(org, 0.0f);
  st.pixel = film_pixel;
  st.sample = sample;
  st.depth = 0u;
  st.flags = PSF_PATH_ALIVE | (params.camera_medium << PSF_PATH_MEDIUM_SHIFT);
  states[j] = st;
  PathVertex none;
  none.position = none.normal = none.albedo = none.alpha = (float4)(0.0f);
  vertices[j] = none;
}
