#version 450
// Reference photo (leafview.app.photo_reference): the photo as one quad in the leaf's plane.
// A corner (0..1, 0..1) of the quad is the photo pixel position corner * photo_size - 1/2 (x
// right, y down, pixel centres at integers), taken to world space by world_from_pixel (the
// photo-to-leaf similarity, then the leaf's transform; leafview.app.photo_reference.
// world_from_pixel is its numpy twin).
uniform mat4 view_proj;
uniform mat4 world_from_pixel;
uniform vec2 photo_size;   // (width, height) in photo pixels that the texture covers

in vec2 in_corner;

out vec2 v_st;             // texture coordinates: s along x, t along y (row 0 of the photo at t = 0)

void main() {
    vec2 px = in_corner * photo_size - 0.5;
    v_st = in_corner;
    gl_Position = view_proj * (world_from_pixel * vec4(px, 0.0, 1.0));
}
