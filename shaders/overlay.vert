#version 450
// Viewport overlays (leafview.app.overlay): control polygons, curves, handles and the ground
// grid, as world-space lines and points with a colour each.
uniform mat4 view_proj;
uniform float point_size;

in vec3 in_pos;
in vec4 in_color;

out vec4 v_color;

void main() {
    v_color = in_color;
    gl_Position = view_proj * vec4(in_pos, 1.0);
    gl_PointSize = point_size;
}
