// A textured rectangle in pixels over the picture: colour bar, help text, status line.

#if defined VERTEX_SHADER

uniform vec2 viewport;       // [pixels]
uniform vec4 rect;           // x, y (top left), width, height [pixels]

in vec2 in_pos;              // unit square corner
out vec2 v_uv;

void main() {
    v_uv = in_pos;
    vec2 p = rect.xy + in_pos * rect.zw;
    gl_Position = vec4(2.0 * p.x / viewport.x - 1.0, 1.0 - 2.0 * p.y / viewport.y, 0.0, 1.0);
}

#elif defined FRAGMENT_SHADER

uniform sampler2D image;     // RGBA, row 0 at the top

in vec2 v_uv;
out vec4 f_color;

void main() {
    f_color = texture(image, v_uv);
}

#endif
