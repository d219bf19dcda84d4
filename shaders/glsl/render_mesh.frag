// `isotile render`'s fragment stage (mesh_render.cpp): the triangle's colour (quality on the ramp
// of colour_ramp.h, normal, or solid), lit by a headlight from both sides, and with WIREFRAME its
// edges darkened about one pixel wide
// (fading out on triangles only a few pixels across).
in vec3 v_bary;
flat in vec3 v_normal;
flat in float v_quality;

uniform vec3 u_ramp[RAMP_SIZE];  // colour_ramp.h's kQualityRamp, in [0, 1]
uniform vec3 u_to_camera;        // unit vector from the scene to the camera (world)
uniform vec3 u_solid;            // COLOUR_SOLID's colour

out vec4 o_colour;

vec3 ramp(float q) {
  float t = clamp(q, 0.0, 1.0) * float(RAMP_SIZE - 1);
  int i = min(int(t), RAMP_SIZE - 2);
  return mix(u_ramp[i], u_ramp[i + 1], t - float(i));
}

void main() {
#if defined(COLOUR_QUALITY)
  vec3 base = ramp(v_quality);
#elif defined(COLOUR_NORMAL)
  vec3 base = 0.5 + 0.5 * v_normal;
#else
  vec3 base = u_solid;
#endif
  // A face seen from behind is lit as its front: holes and open borders stay readable.
  float light = 0.35 + 0.65 * abs(dot(v_normal, u_to_camera));
  vec3 colour = base * light;
#ifdef WIREFRAME
  vec3 d = fwidth(v_bary);
  vec3 a = smoothstep(vec3(0.0), d * 1.2, v_bary);
  float edge = 1.0 - min(min(a.x, a.y), a.z);
  // Triangles a few pixels across would be all edge: their lines fade out between 4 and 2
  // pixels, so a dense mesh seen whole shows its colours, not a dark cloud.
  float fade = 1.0 - clamp(max(max(d.x, d.y), d.z) * 4.0 - 1.0, 0.0, 1.0);
  colour = mix(colour, vec3(0.08), edge * 0.85 * fade);
#endif
  o_colour = vec4(colour, 1.0);
}
