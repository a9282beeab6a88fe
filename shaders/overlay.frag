#version 450
// Viewport overlays: flat colour; points are drawn as round dots with a dark rim.
uniform bool round_points;

in vec4 v_color;

out vec4 frag_color;

void main() {
    vec4 c = v_color;
    if (round_points) {
        float r = length(gl_PointCoord - vec2(0.5)) * 2.0;
        if (r > 1.0) discard;
        c.rgb *= r > 0.65 ? 0.25 : 1.0;
    }
    frag_color = c;
}
