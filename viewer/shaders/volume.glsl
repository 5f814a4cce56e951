// Back-face ray casting of the evidence grid (one program per mode: MODE_OCCUPANCY, MODE_MIP,
// MODE_ISO, MODE_FREE; SKIP turns on empty-space skipping). The box's back faces are drawn with front
// faces culled, so every pixel the box covers runs this shader once, also with the camera
// inside the box. The fragment knows where its ray leaves; the ray's entry comes from
// intersecting it with the clip box, clamped to the camera (t >= 0).
//
// Coordinates: u, in voxels, u = (world - origin) / voxel in [0, dims]; voxel i's centre is
// u = i + 0.5, texture coordinate u / dims: the texel centre. Samples lie at
// t_k = t_near + (k + 0.5) * step along the unit direction in u: the naive and the skipping
// march take the same samples, so skipping changes time, not pixels.

#if defined VERTEX_SHADER

uniform mat4 mvp;            // world -> clip
uniform vec3 origin;         // world of u = 0 [m]
uniform float voxel;         // [m]
uniform vec3 dims;           // voxels along x, y, z

in vec3 in_pos;              // unit cube corner
out vec3 v_u;

void main() {
    v_u = in_pos * dims;
    gl_Position = mvp * vec4(origin + v_u * voxel, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler3D volume;    // log-odds [nat], linear, clamp to edge
uniform sampler3D coarse;    // per 8^3 brick: max over the brick and a one-voxel apron, nearest
uniform sampler3D coarser;   // per 4^3 bricks (32^3 voxels): max of their coarse cells, nearest
uniform sampler2D colormap;  // 256 x 1 RGB
uniform vec3 dims;
uniform vec3 camera_u;       // the eye in voxel units
uniform vec3 clip_lo;        // kept box [voxels]
uniform vec3 clip_hi;
uniform vec3 active_lo;      // the part of the clip box where this mode can see anything [voxels]
uniform vec3 active_hi;
uniform float lo;            // clamp [nat]
uniform float free_lo;       // the free haze's clamp on -v [nat]
uniform float free_hi;
uniform bool by_height;      // iso: colour by height (else by log-odds: a planar map)
uniform float hi;
uniform float gamma;
uniform float density;       // opacity per voxel of length at x = 1
uniform float threshold;     // isosurface [nat]
uniform vec2 height_range;   // iso: the z [voxels] the colormap spans (the content's heights)
uniform float step_u;        // between samples [voxels]
uniform vec3 background;

in vec3 v_u;
out vec4 f_color;

const float BRICK = 8.0;
const float BIG = 32.0;      // voxels per coarser cell
const float OPAQUE = 0.99;
const vec3 FREE_COLOUR = vec3(0.25, 0.6, 1.0);
const float FREE_DENSITY = 0.12;   // free space is a haze: this much of the occupied opacity

float sample_at(vec3 u) { return texture(volume, u / dims).r; }

// the transfer function: clamp -> normalise -> gamma
float transfer(float v) { return pow(clamp((v - lo) / (hi - lo), 0.0, 1.0), gamma); }

vec3 color_of(float x) { return texture(colormap, vec2(x, 0.5)).rgb; }

// the range of t inside the box [a, b] for a ray from `from` along a direction with inverse `inv`
vec2 slab(vec3 from, vec3 inv, vec3 a, vec3 b) {
    vec3 ta = (a - from) * inv, tb = (b - from) * inv;
    vec3 tmin = min(ta, tb), tmax = max(ta, tb);
    return vec2(max(max(tmin.x, tmin.y), max(tmin.z, 0.0)), min(min(tmax.x, tmax.y), tmax.z));
}

void main() {
    vec3 dir = normalize(v_u - camera_u);
    dir = mix(dir, vec3(1e-7), lessThan(abs(dir), vec3(1e-7)));  // no 0 * inf below
    vec3 inv = 1.0 / dir;
    float t_near = slab(camera_u, inv, clip_lo, clip_hi).x;      // the sample lattice's origin
    vec2 t_active = slab(camera_u, inv, active_lo, active_hi);
    int k = max(0, int(ceil((t_active.x - t_near) / step_u - 0.5)));
    int n = int(ceil((t_active.y - t_near) / step_u - 0.5));    // samples with t_k < t_far
#if defined SKIP
    ivec3 cells = textureSize(coarse, 0), cells2 = textureSize(coarser, 0);
    vec3 far_side = step(0.0, dir);                            // the side a ray leaves a cell by
#endif

// EMPTY(cmax): no sample in a cell of maximum cmax can change the pixel
#if defined MODE_OCCUPANCY
    vec3 acc = vec3(0.0);
    float alpha = 0.0;
#define EMPTY(cmax) ((cmax) <= lo)             /* every sample has x = 0 */
#elif defined MODE_MIP
    float best = lo;                          // only values above lo show
#define EMPTY(cmax) ((cmax) <= best)           /* nothing there beats the max so far */
#elif defined MODE_ISO
    float t_hit = -1.0;
#define EMPTY(cmax) ((cmax) < threshold)       /* no sample reaches the surface */
#elif defined MODE_FREE
    vec3 acc = vec3(0.0);
    float alpha = 0.0;
#define EMPTY(cmax) (false)                    /* the maxima say nothing of free space: never skip */
#endif

    while (k < n) {
        float t = t_near + (float(k) + 0.5) * step_u;
        vec3 u = camera_u + t * dir;
#if defined SKIP
        // a cell whose largest readable value this mode cannot see is jumped over, coarser first
        ivec3 cell2 = clamp(ivec3(floor(u / BIG)), ivec3(0), cells2 - 1);
        float cmax = texelFetch(coarser, cell2, 0).r;
        float size = BIG;
        vec3 corner = vec3(cell2);
        if (!EMPTY(cmax)) {
            ivec3 cell = clamp(ivec3(floor(u / BRICK)), ivec3(0), cells - 1);
            cmax = texelFetch(coarse, cell, 0).r;
            size = BRICK;
            corner = vec3(cell);
        }
        if (EMPTY(cmax)) {
            vec3 t_exit3 = ((corner + far_side) * size - camera_u) * inv;
            float t_exit = min(t_exit3.x, min(t_exit3.y, t_exit3.z));
            k = max(k + 1, int(ceil((t_exit - t_near) / step_u - 0.5)));
            continue;
        }
#endif
        float v = sample_at(u);
#if defined MODE_OCCUPANCY
        float x = transfer(v);
        float a = 1.0 - pow(1.0 - min(x * density, 0.999), step_u);   // opacity for this step length
        acc += (1.0 - alpha) * a * color_of(x);
        alpha += (1.0 - alpha) * a;
        if (alpha > OPAQUE) break;
#elif defined MODE_FREE
        // occupied (v > lo) as in occupancy; free (v < -free_lo) as a blue haze of its own clamp on -v
        float x = transfer(v), xf = pow(clamp((-v - free_lo) / (free_hi - free_lo), 0.0, 1.0), gamma);
        float a = 1.0 - pow(1.0 - min(max(x * density, xf * density * FREE_DENSITY), 0.999), step_u);
        acc += (1.0 - alpha) * a * (x > 0.0 ? color_of(x) : FREE_COLOUR);
        alpha += (1.0 - alpha) * a;
        if (alpha > OPAQUE) break;
#elif defined MODE_MIP
        best = max(best, v);
#elif defined MODE_ISO
        if (v >= threshold) {
            // bisection between the previous sample (below the threshold) and this one
            float a = t - step_u, b = t;
            for (int i = 0; i < 6; i++) {
                float m = 0.5 * (a + b);
                if (sample_at(camera_u + m * dir) >= threshold) b = m; else a = m;
            }
            t_hit = t - step_u < t_near ? t : b;
            break;
        }
#endif
        k++;
    }

#if defined MODE_OCCUPANCY || defined MODE_FREE
    f_color = vec4(acc + (1.0 - alpha) * background, 1.0);
#elif defined MODE_MIP
    f_color = vec4(best > lo ? color_of(transfer(best)) : background, 1.0);
#elif defined MODE_ISO
    if (t_hit < 0.0) {
        f_color = vec4(background, 1.0);
    } else {
        vec3 u = camera_u + t_hit * dir;
        vec3 g = vec3(sample_at(u + vec3(1, 0, 0)) - sample_at(u - vec3(1, 0, 0)),
                      sample_at(u + vec3(0, 1, 0)) - sample_at(u - vec3(0, 1, 0)),
                      sample_at(u + vec3(0, 0, 1)) - sample_at(u - vec3(0, 0, 1)));
        float lit = length(g) > 0.0 ? abs(dot(normalize(g), dir)) : 1.0;   // headlight, both sides
        float h = (u.z - height_range.x) / max(height_range.y - height_range.x, 1e-3);
        float c = by_height ? clamp(h, 0.0, 1.0) : transfer(sample_at(u + 0.5 * dir));
        f_color = vec4(color_of(c) * (0.3 + 0.7 * lit), 1.0);
    }
#endif
}

#endif
