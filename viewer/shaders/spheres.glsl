// The paper's Fig. 11: one sphere per cell with positive log-odds, drawn instanced. Radius is
// proportional to the log-odds: half a voxel at `hi`, so spheres of neighbouring cells at the
// clamp just touch. Colour is the transfer function of the value. Cells outside the clip box
// (slices) are moved outside the clip volume.

#if defined VERTEX_SHADER

uniform mat4 mvp;
uniform float voxel;         // [m]
uniform float hi;            // log-odds of the largest sphere [nat]
uniform float gamma;
uniform vec3 clip_lo;        // kept box, world [m]
uniform vec3 clip_hi;

in vec3 in_pos;              // unit sphere vertex, also its normal
in vec3 in_centre;           // per instance: the cell's centre, world [m]
in float in_value;           // per instance: log-odds [nat]
out vec3 v_normal;
out float v_x;

void main() {
    float r = 0.5 * voxel * clamp(in_value / hi, 0.0, 1.0);
    v_normal = in_pos;
    v_x = pow(clamp(in_value / hi, 0.0, 1.0), gamma);
    bool kept = all(greaterThanEqual(in_centre, clip_lo)) && all(lessThanEqual(in_centre, clip_hi));
    gl_Position = kept ? mvp * vec4(in_centre + r * in_pos, 1.0) : vec4(2.0, 2.0, 2.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D colormap;
uniform vec3 light;          // towards the light, world, unit

in vec3 v_normal;
in float v_x;
out vec4 f_color;

void main() {
    float lit = 0.35 + 0.65 * max(dot(normalize(v_normal), light), 0.0);
    f_color = vec4(texture(colormap, vec2(v_x, 0.5)).rgb * lit, 1.0);
}

#endif
