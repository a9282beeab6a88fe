#version 450
// Vein tubes, pass 2 of 2: generalised cylinders swept along the vein polylines, offset from the
// blade (Hong 2005, ch. 6.1). One instance per tube segment (its two end frames, computed from
// the segment's (u, v) by vein_tube_frame.vert), drawn as a triangle strip of 2 (sides + 1)
// vertices: vertex j is ring vertex k = (j / 2) mod sides at the segment's end j mod 2, at angle
// t_k = pi/2 + 2 pi (k - 1/2) / sides from the binormal towards the normal (a face centred on top).
// Numpy twin: leafview/botany/vein_tubes.py.
#include "generated/leaf_block.glsl"
#include "generated/frame_block.glsl"

in vec4 in_ca;   // per instance: ring centre at a (leaf space), radius at a
in vec3 in_na;   // per instance: normal at a
in vec3 in_ba;   // per instance: binormal at a
in vec4 in_cb;   // per instance: the same at b
in vec3 in_nb;
in vec3 in_bb;
uniform int sides;   // ring sides of this draw (its level-of-detail bucket)

out vec3 v_object;          // leaf-space position (captured for tests)
out vec3 v_object_normal;   // leaf-space outward tube normal
out vec3 v_world;
out vec3 v_normal;
out float v_upper;          // the tube normal's component along the blade's upper normal
flat out vec4 v_front;      // rgb, translucency
flat out vec3 v_back;

void main() {
    int k = (gl_VertexID >> 1) % sides;
    bool far_end = (gl_VertexID & 1) != 0;
    vec4 c = far_end ? in_cb : in_ca;
    vec3 n = far_end ? in_nb : in_na;
    vec3 b = far_end ? in_bb : in_ba;
    float theta = 1.5707963267948966 + 6.283185307179586 * (float(k) - 0.5) / float(sides);
    float s = sin(theta);
    vec3 d = cos(theta) * b + s * n;
    vec3 pos = c.xyz + c.w * d;
    v_object = pos;
    v_object_normal = d;
    v_upper = s;
    vec4 world = vec4(mat4x3(leaf.model) * vec4(pos, 1.0), 1.0);
    v_world = world.xyz;
    v_normal = normalize(mat3(leaf.model) * d);
    v_front = leaf.front;
    v_back = leaf.back.rgb;
    gl_Position = frame.proj * frame.view * world;
}
