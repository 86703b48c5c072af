#include "fit/woven_fit.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>

#include "render/reference/fabric.h"

namespace clothfit::fit {
namespace {

std::vector<std::string> Union(std::vector<std::string> a, const std::vector<std::string>& b) {
  for (const std::string& s : b)
    if (std::find(a.begin(), a.end(), s) == a.end()) a.push_back(s);
  return a;
}

}  // namespace

std::string AttachWeaveMaps(const std::string& fabric_path, const std::string& maps_path,
                            FitOptions* options, const WeaveBakeOptions& bake) {
  if (options->start.model != render::ModelKind::kWoven)
    throw FitError("AttachWeaveMaps: the start preset is not a woven preset");
  const render::Fabric fabric = render::LoadFabric(fabric_path);
  const auto* irawan = dynamic_cast<const render::IrawanBsdf*>(fabric.bsdf.get());
  if (!irawan) return "";
  const WeaveBakeResult r = BakeWeaveMaps(*irawan, options->start, bake);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", r.error_mapped);
  render::WriteWeaveMaps(maps_path, r.maps,
                         {{"clothfit:fabric", fabric_path}, {"clothfit:bake_error_mapped", buf}});
  const nlohmann::json source = {{"fabric", fabric_path},
                                 {"weave", irawan->pattern().name},
                                 {"texels", r.maps.size},
                                 {"pairs", r.pairs},
                                 {"bake_error_uniform", r.error_uniform},
                                 {"bake_error_mapped", r.error_mapped},
                                 {"mode", std::string(bake.indicator ? "indicator" : "fitted") +
                                              (bake.relief ? " + relief normals" : "") +
                                              (bake.glint ? " + glint" : "") +
                                              (bake.view_bands ? " + view bands" : "")},
                                 {"lobes_from", "the start preset (woven defaults)"}};
  nlohmann::json src = source;
  if (bake.view_band >= 0) {  // measurement: one view cosine's pairs only
    src["view_band"] = bake.view_band;
    src["view_band_cosine"] = WeaveViewBandCosine(bake.view_band, bake.mu_nodes);
  }
  options->start.extra["weave_maps"] = render::WeaveMapsPresetField(maps_path, r.maps, src);
  if (r.maps.has_glint()) {
    std::string glint = maps_path;
    const size_t dot = glint.rfind(".weave.exr");
    glint = (dot != std::string::npos ? glint.substr(0, dot) : glint) + ".glint.exr";
    render::WriteGlintMap(glint, r.maps);
    options->start.extra["weave_maps"]["glint_file"] =
        std::filesystem::absolute(glint).lexically_normal().string();
    options->start.extra["weave_maps"]["glint_size"] = r.maps.glint_size;
  }
  char line[512];
  std::snprintf(line, sizeof line,
                "weave maps: %s, %dx%d texels per period, %d direction pairs per texel, "
                "BRDF-space error uniform %.4f -> mapped %.4f (cube-root units), %.2f s",
                maps_path.c_str(), r.maps.size, r.maps.size, r.pairs, r.error_uniform,
                r.error_mapped, r.seconds);
  return line;
}

namespace {

bool Has(const std::vector<std::string>& v, const char* name) {
  return std::find(v.begin(), v.end(), name) != v.end();
}

// The two stages (yarn, then sheen) from `options` (its start preset and start roughness
// values), over `prepared`; seconds and setup_seconds exclude the preparation.
FitResult FitTwoStages(const std::vector<SceneInput>& inputs, const FitOptions& options,
                       const PreparedScenes* prepared) {
  FitOptions yarn = options;
  yarn.locked = Union(options.locked, {"anisotropy", "twist", "sheen_color", "sheen_roughness",
                                       "diffuse_roughness"});
  FitResult r1 = FitImages(inputs, yarn, prepared);
  if (!r1.usable) return r1;

  FitOptions sheen = options;
  sheen.start = r1.preset;
  sheen.init_from_reference = false;
  sheen.start_roughness = {0.0};  // unused without init_from_reference: one start
  const int off = sheen.start.Offset("sheen_color");
  for (int c = 0; c < 3; ++c)
    sheen.start.values[size_t(off + c)] = std::max(sheen.start.values[size_t(off + c)], 0.02);
  sheen.locked = Union(options.locked, {"roughness", "anisotropy", "twist", "warp_share",
                                        "specular_f0", "forward_scattering",
                                        "diffuse_roughness"});
  FitResult r2 = FitImages(inputs, sheen, prepared);
  const double seconds = r1.seconds + r2.seconds, setup = r1.setup_seconds + r2.setup_seconds;
  const int iterations = r1.iterations + r2.iterations, starts = r1.starts + r2.starts;
  FitResult best = (r2.usable && r2.rmse < r1.rmse) ? std::move(r2) : std::move(r1);
  best.seconds = seconds;
  best.setup_seconds = setup;
  best.iterations = iterations;
  best.starts = starts;
  return best;
}

FitResult::Candidate CandidateOf(const std::string& name, const FitResult& r) {
  return {name, r.usable ? r.rmse : std::numeric_limits<double>::quiet_NaN(),
          r.seconds - r.setup_seconds, r.iterations};
}

// Makes `r` the result when it is usable with a lower RMSE than `into`; the costs (seconds,
// iterations, starts) and the candidate lists add up either way.
void TakeBetter(FitResult&& r, FitResult& into) {
  const double seconds = into.seconds + r.seconds, setup = into.setup_seconds + r.setup_seconds;
  const int iterations = into.iterations + r.iterations, starts = into.starts + r.starts;
  std::vector<FitResult::Candidate> candidates = into.candidates;
  candidates.insert(candidates.end(), r.candidates.begin(), r.candidates.end());
  if (r.usable && (!into.usable || r.rmse < into.rmse)) into = std::move(r);
  into.seconds = seconds;
  into.setup_seconds = setup;
  into.iterations = iterations;
  into.starts = starts;
  into.candidates = std::move(candidates);
}

}  // namespace

bool UsesClothBasinStart(const FitOptions& options) {
  return options.cloth_basin_start && options.init_from_reference &&
         options.start.model == render::ModelKind::kWoven &&
         !Has(options.locked, "sheen_color") && !Has(options.locked, "sheen_roughness") &&
         !Has(options.locked, "specular_color");
}

FitOptions ClothBasinOptions(const FitOptions& options) {
  FitOptions c = options;
  const int off = c.start.Offset("specular_color");
  for (int k = 0; k < 3; ++k) c.start.values[size_t(off + k)] = 0.0;  // yarn lobes off
  c.locked = Union(options.locked, {"specular_color", "roughness", "anisotropy", "twist",
                                    "warp_share", "specular_f0", "forward_scattering",
                                    "diffuse_roughness"});
  c.init_from_reference = true;  // base from the reference, sheen colour 0.5: cloth's start
  c.start_roughness = {kClothBasinSheenRoughness};  // the sheen roughness (roughness is locked)
  return c;
}

FitOptions FromClothBasin(const FitOptions& options, const render::MaterialPreset& basin) {
  FitOptions from = options;
  from.start = basin;
  const int off = from.start.Offset("specular_color");
  for (int k = 0; k < 3; ++k)  // the yarn lobes back on at the start preset's colour
    from.start.values[size_t(off + k)] = options.start.values[size_t(off + k)];
  from.init_from_reference = false;
  from.start_roughness = {0.0};  // unused without init_from_reference: one start
  return from;
}

FitOptions DiffuseStageOptions(const FitOptions& options, const render::MaterialPreset& from) {
  FitOptions d = options;
  d.start = from;
  d.init_from_reference = false;
  d.start_roughness = {0.0};  // unused without init_from_reference: one start
  d.locked = Union(options.locked, {"specular_color", "roughness", "anisotropy", "twist",
                                    "warp_share", "specular_f0", "forward_scattering"});
  return d;
}

FitOptions LobeShapeStageOptions(const FitOptions& options, const render::MaterialPreset& from,
                                 bool with_share) {
  FitOptions s = options;
  s.start = from;
  s.init_from_reference = false;
  s.start_roughness = {0.0};  // unused without init_from_reference: one start
  s.locked = Union(options.locked, {"twist", "forward_scattering", "sheen_color",
                                    "sheen_roughness", "diffuse_roughness"});
  if (!with_share) s.locked = Union(s.locked, {"warp_share", "specular_f0"});
  return s;
}

FitResult FitWovenImages(const std::vector<SceneInput>& inputs, const FitOptions& options,
                         const PreparedScenes* given) {
  if (options.start.model != render::ModelKind::kWoven)
    throw FitError("FitWovenImages: the start preset is not a woven preset");
  // Every path fits over the same caches, blocks and targets: built once (or the caller's).
  std::shared_ptr<const PreparedScenes> own;
  if (!given) own = PrepareScenes(inputs, options);
  const PreparedScenes* const prepared = given ? given : own.get();
  // The stages after the two (rough diffuse, lobe shape), from a result `r`: each kept only
  // when it lowers the RMSE. `rough_diffuse` false: the lobe-shape stages only (the branches
  // of several starts below, whose best gets the rough-diffuse stage in the second round).
  auto finish = [&](FitResult r, bool rough_diffuse = true) {
    if (r.usable && rough_diffuse && !Has(options.locked, "diffuse_roughness")) {
      // The rough-diffuse stage (session 18): from the best result, the diffuse roughness free
      // with the colours it trades against (docs/fitting.md "A rough diffuse for woven").
      FitResult rough = FitImages(inputs, DiffuseStageOptions(options, r.preset), prepared);
      rough.candidates = {CandidateOf("rough-diffuse", rough)};
      TakeBetter(std::move(rough), r);
    }
    if (r.usable && !Has(options.locked, "anisotropy")) {
      // The lobe-shape stage (session 25, woven_fit.h): the GGX yarn lobes' anisotropy free,
      // first with the roughness and colours, then also with warp_share and f0.
      FitResult shape =
          FitImages(inputs, LobeShapeStageOptions(options, r.preset, false), prepared);
      shape.candidates = {CandidateOf("lobe-shape", shape)};
      TakeBetter(std::move(shape), r);
      FitResult share =
          FitImages(inputs, LobeShapeStageOptions(options, r.preset, true), prepared);
      share.candidates = {CandidateOf("lobe-shape+share", share)};
      TakeBetter(std::move(share), r);
    }
    return r;
  };
  // The cloth basin (woven_fit.h; docs/fitting.md "Woven's starts (session 13)").
  auto cloth_basin = [&]() {
    FitResult basin = FitImages(inputs, ClothBasinOptions(options), prepared);
    basin.candidates = {CandidateOf("cloth-basin", basin)};
    return basin;
  };
  auto from_basin = [&](FitResult& basin) {
    FitResult nested = FitTwoStages(inputs, FromClothBasin(options, basin.preset), prepared);
    nested.candidates = {CandidateOf("cloth-basin+two-stage", nested)};
    TakeBetter(std::move(nested), basin);
  };
  // Several start roughness values (session 26): the best start after one stage is not always
  // the best at the end (canvas on Cycles yarns, no maps: the 0.3 start wins the stages before
  // the lobe shape and loses after it, 0.0092 against 0.0086), so each start, and the cloth
  // basin, runs the pipeline (without the rough-diffuse stage: the same results to 0.3 %,
  // 15-30 % faster), the lowest RMSE is kept, and the whole pipeline runs once more from it. With the roughness locked
  // (the fabric's far-field lobe) or an explicit --start the starts are one start (FitImages
  // runs identical start points once), and the pipeline is the session-25 one.
  const bool per_start = options.start_roughness.size() > 1 && options.init_from_reference &&
                         !Has(options.locked, "roughness");
  FitResult best;
  if (!per_start) {
    best = FitTwoStages(inputs, options, prepared);
    best.candidates = {CandidateOf("two-stage", best)};
    if (UsesClothBasinStart(options)) {
      FitResult basin = cloth_basin();
      if (basin.usable && (!best.usable || basin.rmse <= kClothBasinContinueRatio * best.rmse))
        from_basin(basin);
      TakeBetter(std::move(basin), best);
    }
    best = finish(std::move(best));
  } else {
    // Each branch's paths are named after it: "start R: two-stage", "start R: lobe-shape",
    // ..., "cloth basin: ...", then "second round: ..." (with its rough-diffuse stage).
    auto prefixed = [](FitResult r, const std::string& prefix) {
      for (FitResult::Candidate& c : r.candidates) c.name = prefix + c.name;
      return r;
    };
    best.usable = false;
    best.message = "no start converged to a usable solution";
    double best_two_stage = std::numeric_limits<double>::infinity();
    std::vector<double> seen;
    for (const double r0 : options.start_roughness) {
      if (std::find(seen.begin(), seen.end(), r0) != seen.end()) continue;  // --starts 0.6,0.6
      seen.push_back(r0);
      FitOptions one = options;
      one.start_roughness = {r0};
      FitResult r = FitTwoStages(inputs, one, prepared);
      r.candidates = {CandidateOf("two-stage", r)};
      if (r.usable) best_two_stage = std::min(best_two_stage, r.rmse);
      char prefix[32];
      std::snprintf(prefix, sizeof prefix, "start %.2g: ", r0);
      TakeBetter(prefixed(finish(std::move(r), false), prefix), best);
    }
    if (UsesClothBasinStart(options)) {
      FitResult basin = cloth_basin();
      if (basin.usable && basin.rmse <= kClothBasinContinueRatio * best_two_stage)
        from_basin(basin);
      TakeBetter(prefixed(finish(std::move(basin), false), "cloth basin: "), best);
    }
    if (best.usable) {
      // A second round of the whole pipeline from the best result (session 26): the later
      // stages hold what the earlier ones fitted (the lobe-shape stages hold the sheen), so
      // one more pass lets each stage answer the others' moves. Measured on the Cycles
      // references of docs/fitting.md "A start for glossy references": 1-12 % lower RMSE than
      // the best branch; a third round would gain 0-4 % more, for another 0.3-1 s: not run.
      FitOptions again = options;
      again.start = best.preset;
      again.init_from_reference = false;  // exactly these values: one start, no cloth basin
      again.start_roughness = {0.0};
      FitResult round2 = FitWovenImages(inputs, again, prepared);
      for (FitResult::Candidate& c : round2.candidates) c.name = "second round: " + c.name;
      TakeBetter(std::move(round2), best);
    }
  }
  if (own) {  // a caller's preparation is the caller's to count
    best.setup_seconds += PreparedSeconds(*own);
    best.seconds += PreparedSeconds(*own);
  }
  return best;
}

void ApplyModelDefaults(FitOptions* o) {
  const render::ModelKind m = o->start.model;
  if (m == render::ModelKind::kStandard || m == render::ModelKind::kPhysicalSheen)
    o->locked.push_back("metalness");
  if (m == render::ModelKind::kGltfSheen) o->locked.push_back("metallic");
  if (m == render::ModelKind::kPhysicalAniso) {
    for (const char* n : {"metalness", "anisotropy_rotation", "specular_color"})
      o->locked.push_back(n);
    o->start.values[size_t(o->start.Offset("anisotropy_strength"))] = 0.5;
  }
}

std::string AttachWeaveMapsToPhysicalAniso(const std::string& fabric_path,
                                           const std::string& maps_path, FitOptions* options) {
  if (options->start.model != render::ModelKind::kPhysicalAniso)
    throw FitError("AttachWeaveMapsToPhysicalAniso: the start preset is not physical-aniso");
  FitOptions wo;
  wo.start = render::DefaultPreset(render::ModelKind::kWoven);
  const std::string line = AttachWeaveMaps(fabric_path, maps_path, &wo, {});
  if (wo.start.extra.contains("weave_maps"))
    options->start.extra["weave_maps"] = wo.start.extra["weave_maps"];
  return line;
}

bool SetMapAnisotropy(int n, FitOptions* options) {
  nlohmann::json& e = options->start.extra;
  if (!e.is_object() || !e.contains("weave_maps") || !e["weave_maps"].is_object()) return false;
  e["weave_maps"]["anisotropy"] = n;
  return true;
}

}  // namespace clothfit::fit
