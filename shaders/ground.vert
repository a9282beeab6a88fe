#version 450
// The ground pass's full-screen triangle (the same as sky.vert: the ground is ray-cast per
// fragment, ground.frag); v_ndc: the fragment's normalised device x, y.
out vec2 v_ndc;

void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2)) * 2.0 - 1.0;
    v_ndc = p;
    gl_Position = vec4(p, 0.0, 1.0);
}
