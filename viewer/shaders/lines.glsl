// Guides drawn over the picture: the ground grid, the axes, the sensor's poses. Coloured lines
// in world coordinates, alpha-blended (viewer/guides.py).

#if defined VERTEX_SHADER

uniform mat4 mvp;            // world -> clip
in vec3 in_pos;              // [m]
in vec4 in_color;            // RGBA
out vec4 v_color;

void main() {
    v_color = in_color;
    gl_Position = mvp * vec4(in_pos, 1.0);
}

#elif defined FRAGMENT_SHADER

in vec4 v_color;
out vec4 f_color;

void main() { f_color = v_color; }

#endif
