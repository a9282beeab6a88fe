#version 450
// Dear ImGui fragments: vertex colour times the bound texture (font atlas or user image).
layout(binding = ATLAS_UNIT) uniform sampler2D atlas;

in vec2 v_uv;
in vec4 v_color;

out vec4 frag_color;

void main() {
    frag_color = v_color * texture(atlas, v_uv);
}
