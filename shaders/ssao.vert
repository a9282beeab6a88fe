#version 450
// One triangle covering the viewport (no vertex attributes: positions from gl_VertexID), for the
// screen-space ambient occlusion passes (ssao.frag, ssao_blur.frag; leafview/gpu/ssao.py).
void main() {
    vec2 corner = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));   // (0,0) (2,0) (0,2)
    gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
