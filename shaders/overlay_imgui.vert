#version 450
// Dear ImGui draw lists (leafview.app.imgui_gl): pixel positions with the origin at the top-left,
// font-atlas uv, 8-bit sRGB vertex colours.
uniform mat4 proj;

in vec2 in_pos;
in vec2 in_uv;
in vec4 in_color;

out vec2 v_uv;
out vec4 v_color;

void main() {
    v_uv = in_uv;
    v_color = in_color;
    gl_Position = proj * vec4(in_pos, 0.0, 1.0);
}
