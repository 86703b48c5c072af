// clothfit fit: fit a material preset so the preview matches path-traced references.
#include <tbb/global_control.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <vector>
#include <sstream>
#include <stdexcept>
#include <string>

#include <unistd.h>

#include "bin/commands.h"
#include "render/scene/sun.h"
#include "bin/visibility_flags.h"  // s9-vis
#include "bin/progress.h"
#include "fit/image_fit.h"
#include "fit/reference.h"
#include "fit/woven_fit.h"
#include "fit/yarn_farfield.h"
#include "render/reference/fabric.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"
#include "render/reference/path_tracer.h"
#include "render/preview/preview.h"
#include "render/preview/weave_maps.h"

namespace clothfit::cli {
namespace fs = std::filesystem;

std::vector<std::string> SplitList(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

namespace {

std::string ReadFileOrEmpty(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

// FNV-1a 64 over a byte string.
uint64_t Fnv1a(const char* p, size_t n, uint64_t h = 0xcbf29ce484222325ull) {
  for (size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(p[i]);
    h *= 0x100000001b3ull;
  }
  return h;
}
uint64_t Fnv1a(const std::string& s) { return Fnv1a(s.data(), s.size()); }

// FNV-1a 64 over a file's bytes, read in 1 MiB chunks (a map is hashed without holding it in
// memory); nullopt when the file cannot be read.
std::optional<uint64_t> FileFnv1a(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return std::nullopt;
  uint64_t h = 0xcbf29ce484222325ull;
  std::vector<char> buf(size_t(1) << 20);
  while (f) {
    f.read(buf.data(), std::streamsize(buf.size()));
    const std::streamsize n = f.gcount();
    if (n <= 0) break;
    h = Fnv1a(buf.data(), size_t(n), h);
  }
  if (f.bad()) return std::nullopt;
  return h;
}

std::string CacheDir() {
  if (const char* d = std::getenv("CLOTHFIT_CACHE")) return d;
  if (const char* home = std::getenv("HOME")) return std::string(home) + "/.cache/clothfit/references";
  return "/tmp/clothfit-references";
}

}  // namespace

// Renders (or reuses) the reference of `fabric_path` on `scene_path`. The cache key hashes
// the contents of every input (scene card, glTF, fabric, weave file) and the settings, so a
// changed input re-renders and an unchanged one never does.
render::Scene LoadSceneAtWidth(const std::string& scene_path, int width) {
  render::Scene scene = render::LoadScene(scene_path);
  if (width > 0 && width != scene.card.width) {
    const double aspect = double(scene.card.height) / double(scene.card.width);
    scene.card.width = width;
    scene.card.height = std::max(1, int(std::lround(width * aspect)));
  }
  return scene;
}

// The card's text for the reference key: the file as it is, or, when it has a "visibility"
// block (session 13: how the engine draws the scene; the reference renderer ignores it), the
// card without that block, dumped canonically, so adding or changing it keeps its references.
std::string CardKeyText(const std::string& scene_path) {
  const std::string text = ReadFileOrEmpty(scene_path);
  try {
    nlohmann::json j = nlohmann::json::parse(text);
    if (!j.is_object() || !j.contains("visibility")) return text;
    j.erase("visibility");
    return "card-without-visibility|" + j.dump();
  } catch (const nlohmann::json::exception&) {
    return text;  // LoadScene has already refused a malformed card
  }
}

std::string CachedReference(const std::string& scene_path, const std::string& fabric_path,
                            int spp, uint64_t seed, bool quiet, int width, double target_error) {
  const render::Scene scene = LoadSceneAtWidth(scene_path, width);
  std::string key_text = "clothfit-reference-v1|renderer=" +
                         std::to_string(render::kReferenceRendererVersion) + "|" + std::to_string(spp) + "|" +
                         std::to_string(seed) + "|" + CardKeyText(scene_path) + "|" +
                         ReadFileOrEmpty(scene.card.gltf) + "|" + ReadFileOrEmpty(fabric_path);
  // The card's own size is already in its content; an override is part of the key.
  if (width > 0) key_text += "|width=" + std::to_string(scene.card.width) + "x" + std::to_string(scene.card.height);
  // The fabric's weave file: the one the loader read ('weave_file', else the default
  // ../weaves/<preset>.weave next to the fabric; session 28: before, always the default, so a
  // fabric with its own 'weave_file' kept its cached references after that file changed).
  // Keys of fabrics without 'weave_file' are unchanged (the same file's bytes).
  const render::Fabric fabric = render::LoadFabric(fabric_path);
  key_text += "|" + (fabric.weave_path.empty() ? std::string() : ReadFileOrEmpty(fabric.weave_path));
  if (scene.card.environment) {
    // What the renderer will draw, not only the card's name for it (session 20): a map's
    // bytes, or the procedural sky that stands in for a map that is not installed. Before,
    // a reference rendered under the stand-in sky (scripts/fetch-data not run yet) was reused
    // under the real map once it was installed.
    const render::EnvironmentSpec& e = *scene.card.environment;
    key_text += "|" + e.path;
    if (e.path == "procedural-sky") {
      key_text += "|procedural-sky";
    } else if (const auto h = e.found ? FileFnv1a(e.path) : std::nullopt) {
      char map_key[48];
      std::snprintf(map_key, sizeof map_key, "|map-fnv1a=%016llx", (unsigned long long)*h);
      key_text += map_key;
    } else {
      key_text += "|not-installed:procedural-sky";
    }
  }
  // Adaptive references: the target and the allocation's constants (spp is the budget).
  render::RenderSettings st;
  if (target_error > 0.0) {
    char adaptive[160];
    std::snprintf(adaptive, sizeof adaptive, "|adaptive target=%.17g min=%d pilot=%d calib=%.17g",
                  target_error, st.min_spp, st.pilot_spp, st.pilot_calibration);
    key_text += adaptive;
  }
  char name[64];
  std::snprintf(name, sizeof name, "%016llx.exr", (unsigned long long)Fnv1a(key_text));
  const std::string dir = CacheDir();
  fs::create_directories(dir);
  const std::string path = (fs::path(dir) / name).string();
  if (fs::exists(path)) return path;
  const auto env = LoadSceneEnvironment(scene, quiet);
  render::PathTracer tracer(scene, *fabric.bsdf, env.get());
  st.spp = spp;
  st.seed = seed;
  st.target_error = target_error;
  ProgressBar bar("reference " + fabric.name + " / " + fs::path(scene_path).stem().string(), quiet);
  const render::RenderResult r = tracer.Render(st, [&](int d, int t) { bar.Update(d, t); });
  // Written under a temporary name and renamed: shards sharing the cache directory (render-
  // references --shard, docs/reference-renderer.md) never read a partly written file.
  const std::string tmp = path.substr(0, path.size() - 4) + ".tmp" + std::to_string(::getpid()) + ".exr";
  render::WriteRenderExr(tmp, r,
                         {{"clothfit:scene", scene_path},
                          {"clothfit:fabric", fabric_path},
                          {"clothfit:fabric_name", fabric.name},
                          {"clothfit:spp", std::to_string(spp)},
                          {"clothfit:seed", std::to_string(seed)},
                          {"clothfit:target_error", std::to_string(target_error)},
                          {"clothfit:mean_spp", std::to_string(r.mean_spp)},
                          {"clothfit:renderer_version", std::to_string(render::kReferenceRendererVersion)}});
  fs::rename(tmp, path);
  if (!quiet)
    std::fprintf(stderr, "clothfit: rendered %s (%.1f s, %.1f spp, mean std error %.2f%% of mean)\n",
                 path.c_str(), r.seconds, r.mean_spp,
                 r.mean_value > 0 ? 100.0 * r.mean_std_error / r.mean_value : 0.0);
  return path;
}

std::vector<std::string> CanonicalScenes() {
  const char* env = std::getenv("CLOTHFIT_DATASETS");
  const std::string root = env ? env : CLOTHFIT_SOURCE_DATASETS;
  return {root + "/scenes/sphere.json", root + "/scenes/drape.json", root + "/scenes/swatch.json"};
}

namespace {

struct FitArgs {
  // --model woven by default (session 27): the project's recommended model (README "Use woven
  // for woven fabrics"; best on another renderer's smooth materials too, docs/fitting.md "A
  // start for glossy references"). Until session 26 it was cloth, which loses to plain three.js
  // materials.
  std::string fabric, references, scenes, model = "woven", space = "display", lock, out;
  std::string level = "auto", loss = "huber", variant = "filament", sheen_default = "explicit";
  std::string images, references2, alpha = "auto", coverage_channel, noise = "auto";
  std::string weave_period, starts, start_values, weave_maps = "auto";
  // Max anisotropy of the weave maps (texture.anisotropy; render/preview/weave_maps.h),
  // written to the preset's weave_maps.anisotropy. Default 16, by measurement (docs/flip.md
  // "Anisotropic filtering of the maps": per-pixel FLIP canvas 0.93x -> 0.83x, twill 0.97x ->
  // 0.90x of the best baseline; block RMSE canvas -0.6 %, twill +1.0 %).
  int map_anisotropy = -1;  // -1: not given (16 where there are maps); given without maps: an error
  int weave_map_view_band = -1;  // measurement: bake the maps from one view cosine's pairs
  bool no_weave_map_views = false;  // --weave-maps auto without the view bands (session 13's maps)
  std::string target_error;  // reference adaptive sampling (TargetErrorFor)
  double loss_scale = 1.0, min_coverage = 0.5;
  bool subsurface = false, no_floor = false, second_seed = false;
  bool no_cloth_basin = false;  // woven: only the two stages (fit/woven_fit.h, session 13)
  int spp = 256, stride = 0, threads = 0, max_iterations = 50;
  int exact_ibl = 0;  // s7-ibl measurement hook (docs/fitting.md "The sphere's error decomposed")
  double sheen_tilt = 0.0;  // s10-velvet: the sheen nap prototype (docs/velvet.md)
  // Session 11: the far-field yarn lobe measurement (fit/yarn_farfield.h; "" = the model's own).
  std::string yarn_lobe = "auto";
  int yarn_lobe_positions = 16;
  int yarn_table_theta = 16, yarn_table_jitter = 0, yarn_quad_nodes = 0;  // 0: the mode's default
  std::string yarn_ibl = "summary";
  // Session 8: the IBL engine of the previews (auto: the engine web/ draws the model with) and
  // woven's IBL integration (docs/fitting.md "Filtered importance sampling for woven's IBL").
  std::string ibl_engine = "auto", woven_ibl = "auto";
  // -1: not given (the FIS defaults apply). Given without --woven-ibl fis: an error, not ignored.
  int fis_taps = -1, fis_diffuse_taps = -1;
  VisibilityFlags visibility;  // s9-vis: --shadows, --ao, --indirect (docs/visibility.md)
  std::string env_sun;  // s10-sun: "" = the cards' environment.sun (else auto); auto | off | panels
};

// woven fits on the three.js IBL engine: the yarn lobes' IBL by the split sum unless
// --woven-ibl fis. FIS is opt-in (docs/fitting.md "Filtered importance sampling for woven's
// IBL (session 8)", "The default"): on the studio it lowers the block-RMSE ratio only from
// 0.730 to 0.718 (canvas) and 0.640 to 0.633 (twill), its 16 taps alias a sun (canvas sphere
// under blender-city 0.0030 -> 0.0048 against the exact IBL), and the web/ shader with 16 taps
// costs 6-7x the split sum's frame time in headless Chromium (docs/web.md).
constexpr woven::IblMode kDefaultWovenIbl = woven::IblMode::kSplit;

void AddFitOptions(CLI::App* cmd, FitArgs& a) {
  cmd->add_option("--fabric", a.fabric,
                  "fabric definition: render (or reuse cached) references on the canonical scenes "
                  "(or on --scenes; with --references too, only the weave maps and period); "
                  "give --fabric or --references");
  cmd->add_option("--references", a.references, "comma-separated reference EXRs");
  cmd->add_option("--scenes", a.scenes,
                  "comma-separated scene cards, one per reference (with --fabric: instead of the "
                  "canonical cards, e.g. under another environment; default with --fabric: "
                  "datasets/scenes/{sphere,drape,swatch}.json)");
  cmd->add_option("--model", a.model,
                  "woven (default) | cloth | standard | physical-sheen | gltf-sheen | "
                  "physical-aniso");
  // Checked whatever the model (session 27): a value that does not apply is still a typo.
  cmd->add_option("--space", a.space, "residual space: display (default) | linear | log")
      ->check(CLI::IsMember({"display", "linear", "log"}));
  cmd->add_option("--lock", a.lock,
                  "comma-separated parameters to hold at their defaults or --start values "
                  "(default: none beyond the model's own locks); locking every free parameter "
                  "fits nothing: "
                  "a warning, exit 0, the preset written at the start values with their error");
  cmd->add_option("--level", a.level,
                  "block level: residuals on 2^level blocks, 0-6 or auto (default auto: from the "
                  "weave scale, else 4)");
  cmd->add_option("--loss", a.loss, "huber (default) | cauchy | none")
      ->check(CLI::IsMember({"huber", "cauchy", "none"}));
  cmd->add_option("--loss-scale", a.loss_scale,
                  "robust loss scale, in noise-floor units (default 1)");
  cmd->add_option("--variant", a.variant, "cloth variant: filament (default) | seed-threejs")
      ->check(CLI::IsMember({"filament", "seed-threejs"}));
  cmd->add_option("--sheen-default", a.sheen_default,
                  "cloth sheen convention: explicit (default: fit it) | sqrt-base-color | white")
      ->check(CLI::IsMember({"explicit", "sqrt-base-color", "white"}));
  cmd->add_flag("--subsurface", a.subsurface, "cloth: fit a subsurface colour too");
  cmd->add_option("--spp", a.spp, "reference samples per pixel (--fabric; default 256)")
      ->check(CLI::Range(16, 65536));
  cmd->add_option("--target-error", a.target_error,
                  "references (--fabric): adaptive sampling to this mean standard error / mean "
                  "value, 'E' or per scene 'sphere=E,drape=E,swatch=E'; --spp is the budget "
                  "(default: none, a fixed --spp)");
  cmd->add_option("--stride", a.stride,
                  "evaluate every n-th pixel per block axis (default 0 = auto: at most 4 x 4 per "
                  "block)")
      ->check(CLI::Range(0, 16));
  cmd->add_flag("--no-noise-floor", a.no_floor, "(--fabric) skip the second-seed references");
  cmd->add_flag("--second-seed", a.second_seed,
                "(--fabric) render second-seed references for the noise floor even when the "
                "references carry half channels (default: the floor from the halves)");
  cmd->add_option("--weave-maps", a.weave_maps,
                  "woven with an Irawan --fabric: auto (default: bake weave maps next to --out, "
                  "per-texel "
                  "fit, and fit with them; fit/weave_maps.h), indicator (analytic yarn-on-top "
                  "maps, no per-texel fit), relief (auto plus a yarn-relief normal map), glint "
                  "(auto plus the reference's glint map) or none (the uniform woven model)")
      ->check(CLI::IsMember({"auto", "indicator", "relief", "glint", "none"}));
  cmd->add_option("--map-anisotropy", a.map_anisotropy,
                  "max anisotropy of the weave maps (woven, physical-aniso with maps), as three.js "
                  "texture.anisotropy: 1 = isotropic (GL's default LOD), 2..16 = anisotropic "
                  "filtering (EXT_texture_filter_anisotropic); written to the preset's "
                  "weave_maps.anisotropy and used by the fit's previews (default 16)")
      ->check(CLI::Range(1, 16));
  cmd->add_option("--weave-map-view-band", a.weave_map_view_band,
                  "measurement (docs/flip.md, session 14): bake the weave maps from the pairs of "
                  "one view cosine only (0, 1, 2: the Gauss-Legendre nodes 0.887, 0.5, 0.113 in "
                  "the bake's order); the preset's weave_maps.source records it")
      ->check(CLI::Range(0, 2));
  cmd->add_flag("--no-weave-map-views", a.no_weave_map_views,
                "woven, --weave-maps auto: bake only the all-views maps (session 13's), not the "
                "view bands (by default the maps are also baked once per view cosine, 0.887, "
                "0.5, 0.113, and drawn blended by NoV; the preset's weave_maps.view_cosines; "
                "docs/preview.md \"View-dependent weave maps\")");
  cmd->add_option("--images", a.images,
                  "directory for fitted previews and residual images (default: none written)");
  cmd->add_option("--threads", a.threads, "worker threads (default 0 = all)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--references2", a.references2,
                  "second renders of the references (another seed): the noise floor (a floor "
                  "above the fit's error is warned about: not the same material and scene)");
  cmd->add_option("--alpha", a.alpha,
                  "reference alpha: auto (default) | premultiplied | straight (docs/references.md)");
  cmd->add_option("--coverage-channel", a.coverage_channel,
                  "reference coverage channel (default: fabric, else A; none: all covered)");
  cmd->add_option("--min-coverage", a.min_coverage,
                  "keep a block when its reference coverage fraction is at least this "
                  "(default 0.5)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--noise", a.noise,
                  "reference noise without stderr.*: auto (default) | image | none");
  cmd->add_option("--weave-period", a.weave_period,
                  "weave period for --level auto: metres (0.002, 2mm) via the cards' "
                  "uv_metres_per_unit, or UV units (0.05uv); default: the --fabric's, else "
                  "unknown");
  cmd->add_option("--max-iterations", a.max_iterations, "solver iterations per start (default 50)")
      ->check(CLI::Range(1, 100000));
  cmd->add_option("--starts", a.starts, "comma-separated start roughness values (default 0.6,0.9,0.3; woven 0.6,0.3)");
  cmd->add_flag("--no-cloth-basin", a.no_cloth_basin,
                "woven: skip the cloth-basin start (yarn lobes off, broad sheen; default on "
                "unless --start)");
  cmd->add_option("--start", a.start_values,
                  "start values: name=value,... (colours as r:g:b, e.g. base_color=0.5:0.4:0.3), "
                  "one start; default: the model's defaults, colours from the references, the "
                  "--starts roughness values");
  cmd->add_option("--exact-ibl", a.exact_ibl,
                  "measurement only: fit with the environment integrated exactly (Monte Carlo, "
                  "this many directions per pixel, seed 1; no split sum); 0 = the engine (default)")
      ->check(CLI::Range(0, 65536));
  cmd->add_option("--yarn-lobe", a.yarn_lobe,
                  "woven's yarn lobes: auto (default: 'preset' when --fabric is an irawan fabric, or a "
                  "sadeghi fabric whose threads share one hue, "
                  "and no --sheen-tilt or --woven-ibl fis|bent, else 'none'; with the visibility "
                  "flags --shadows, --ao, --indirect too), "
                  "none (woven's anisotropic GGX lobes), preset (the fabric's far-field lobe "
                  "written into the preset, \"woven\": {\"yarn_lobe\"}: irawan, a deterministic quadrature; "
                  "sadeghi, the microcylinder BSDF in closed form; for lights, its table's split sum for the environment; brdf/yarn_lobe.h, drawn "
                  "by web/clothfit.js too). Measurement only: 'farfield' "
                  "replaces the yarn lobes by the fabric's period-averaged Irawan specular "
                  "(fit/yarn_farfield.h; needs --exact-ibl), 'table' by that lobe tabulated "
                  "(brdf/yarn_table.h) with its own split-sum IBL, 'farfield-split' the far-field lobe "
                  "for lights and the table's split sum for the environment, 'quadrature' the same with "
                  "the lobe by a deterministic quadrature (YarnFarField::EvalQuadrature; the "
                  "table baked from it); roughness, anisotropy, twist, "
                  "specular_f0 and forward_scattering locked (no effect) in every mode but none")
      ->check(CLI::IsMember({"auto", "none", "preset", "farfield", "table", "farfield-split",
                             "quadrature"}));
  cmd->add_option("--yarn-quad-nodes", a.yarn_quad_nodes,
                  "--yarn-lobe preset|quadrature: nodes per yarn group (default: preset 8, "
                  "quadrature 16; web/ evaluates them per fragment and light)")
      ->check(CLI::Range(1, 64));
  cmd->add_option("--yarn-ibl", a.yarn_ibl,
                  "--yarn-lobe table|farfield-split|quadrature: the environment by the table's "
                  "one-read summary per lobe (summary, default) or one read per wi bin (bins)")
      ->check(CLI::IsMember({"summary", "bins"}));
  cmd->add_option("--yarn-table-theta", a.yarn_table_theta,
                  "--yarn-lobe preset|table|...: theta bins of wo and wi (phi: twice as many; "
                  "default 16)")
      ->check(CLI::Range(2, 64));
  cmd->add_option("--yarn-table-jitter", a.yarn_table_jitter,
                  "--yarn-lobe table: 0 = bin-centre values (default), N = each entry the mean of N "
                  "(wo, wi) pairs within its bins")
      ->check(CLI::Range(0, 4096));
  cmd->add_option("--yarn-lobe-positions", a.yarn_lobe_positions,
                  "weave positions per far-field evaluation (a square; default 16)")
      ->check(CLI::Range(1, 4096));
  AddVisibilityFlags(cmd, a.visibility);  // s9-vis: measurement flags (bin/visibility_flags.h)
  cmd->add_option("--sheen-tilt", a.sheen_tilt,
                  "measurement (cloth, woven): the sheen lobe's normal tilted this many degrees "
                  "towards the mesh tangent +u, a nap (docs/velvet.md); 0 = none (default)")
      ->check(CLI::Range(-90.0, 90.0));
  cmd->add_option("--ibl-engine", a.ibl_engine,
                  "whose image-based lighting the previews reproduce: auto (default: three.js "
                  "r187's PMREM for standard, physical-sheen, physical-aniso, woven and the "
                  "seed cloth, as web/ draws them; Filament for the Filament cloth and "
                  "gltf-sheen), threejs or filament")
      ->check(CLI::IsMember({"auto", "threejs", "filament"}));
  cmd->add_option("--env-sun", a.env_sun,
                  "s10-sun: the environment's sun as a directional light in the previews "
                  "(docs/sun.md): auto, off or panels (auto, then broad bright sources such as "
                  "softboxes as more lights); default: each card's environment.sun, else auto. "
                  "Recorded as fit.env_sun (\"card\" without the flag; evaluate reuses it)");
  cmd->add_option("--woven-ibl", a.woven_ibl,
                  "woven's yarn-lobe IBL on the three.js engine: auto (default: split), fis "
                  "(filtered importance sampling of the PMREM), split (split sum) or bent (split "
                  "sum about each yarn lobe's bent normal, three.js getIBLAnisotropyRadiance "
                  "style; brdf/woven.h IblMode::kBent)")
      ->check(CLI::IsMember({"auto", "fis", "split", "bent"}));
  cmd->add_option("--fis-taps", a.fis_taps, "woven FIS: yarn-lobe taps (1-64; default 16)")
      ->check(CLI::Range(1, woven::kMaxFisTaps));
  cmd->add_option("--fis-diffuse-taps", a.fis_diffuse_taps,
                  "woven FIS: diffuse irradiance taps (default 0 = the engine's irradiance; 0-64)")
      ->check(CLI::Range(0, woven::kMaxFisTaps));
  cmd->add_option("--out", a.out,
                  "output preset JSON (its directory must exist and be writable, and it must not "
                  "be one of the inputs; checked before any work)")
      ->required();
}

render::IblEngine ParseIblEngine(const std::string& s) {
  if (s == "auto") return render::IblEngine::kAuto;
  if (s == "threejs") return render::IblEngine::kThreejs;
  if (s == "filament") return render::IblEngine::kFilament;
  throw std::invalid_argument("--ibl-engine: unknown '" + s + "' (auto, threejs, filament)");
}

// A number, or an invalid_argument naming the flag and the text.
double ParseNumber(const std::string& text, const std::string& flag) {
  size_t used = 0;
  double x = 0.0;
  try {
    x = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(x))
    throw std::invalid_argument(flag + ": '" + text + "' is not a number");
  return x;
}

// --starts and --start (exclusive): the multi-start roughness values, or one start from the
// given values (unnamed parameters at the model's defaults).
void ApplyStarts(const FitArgs& a, fit::FitOptions* o) {
  if (!a.starts.empty()) {
    o->start_roughness.clear();
    for (const std::string& v : SplitList(a.starts)) {
      const double r = ParseNumber(v, "--starts");
      if (!(r >= 0.0 && r <= 1.0))
        throw std::invalid_argument("--starts: '" + v + "' is not a roughness in [0, 1]");
      o->start_roughness.push_back(r);
    }
  }
  if (a.start_values.empty()) return;
  if (!a.starts.empty())
    throw std::invalid_argument("--start and --starts are exclusive: give the roughness in "
                                "--start (roughness=0.7)");
  nlohmann::json params = nlohmann::json::object();
  for (const std::string& item : SplitList(a.start_values)) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0)
      throw std::invalid_argument("--start: '" + item + "' is not name=value");
    std::vector<double> comps;
    std::stringstream vs(item.substr(eq + 1));
    std::string comp;
    while (std::getline(vs, comp, ':')) comps.push_back(ParseNumber(comp, "--start " + item));
    params[item.substr(0, eq)] = comps.size() == 1 ? nlohmann::json(comps[0]) : nlohmann::json(comps);
  }
  nlohmann::json pj = {{"schema", "clothfit.preset"}, {"version", 1},
                       {"model", render::ToString(o->start.model)}, {"parameters", params}};
  if (o->start.model == render::ModelKind::kCloth)
    pj["cloth"] = {{"variant", a.variant}, {"sheen_default", a.sheen_default},
                   {"subsurface", a.subsurface}};
  o->start.values = render::ParsePreset(pj, "--start").values;
  o->init_from_reference = false;  // exactly these values, one start
  o->start_roughness = {0.0};
}

// --level: an integer in [0, 6], or -1 for "auto" (validated before any work).
int ParseFixedLevel(const std::string& level) {
  int fixed_level = -1;
  if (level != "auto") {
    size_t used = 0;
    try {
      fixed_level = std::stoi(level, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != level.size() || fixed_level < 0 || fixed_level > 6)
      throw std::invalid_argument("--level: '" + level + "' is not an integer in [0, 6] or auto");
  }
  return fixed_level;
}

// The files to fit: scene cards, references and second-seed references (may be empty).
struct FitFiles {
  std::vector<std::string> refs, refs2, scenes;
  bool given = false;  // --references (else the fit rendered them from --fabric)
};

// Whether a reference was rendered by clothfit from this fabric: its EXR names the fabric, by
// `clothfit:fabric_name` (render-reference) or by the file stem of `clothfit:fabric` (the
// reference cache, render-references), equal to the fabric's name or file stem. Returns ""
// when it does, else why not (for the log). Another renderer's images carry neither.
// `fabric_name`: the fabric's own name (render::Fabric::name), loaded once by the caller.
std::string ForeignReference(const std::string& ref, const std::string& fabric_path,
                             const std::string& fabric_name) {
  const std::string stem = fs::path(fabric_path).stem().string();
  const io::Image img = io::ReadImage(ref);
  auto get = [&](const char* k) {
    const auto it = img.metadata.find(k);
    return it == img.metadata.end() ? std::string() : it->second;
  };
  const std::string name = get("clothfit:fabric_name");
  const std::string from = fs::path(get("clothfit:fabric")).stem().string();
  for (const std::string& n : {name, from})
    if (!n.empty() && (n == fabric_name || n == stem)) return "";
  if (name.empty() && from.empty()) return ref + " has no clothfit:fabric metadata";
  return ref + " was rendered from fabric '" +
         limits::EscapeForMessage(name.empty() ? from : name, 80) + "', not '" +
         limits::EscapeForMessage(fabric_name, 80) + "'";
}

// --fabric: references rendered (or reused) on the canonical scenes; --fabric --scenes S,...:
// rendered (or reused) on those cards instead (e.g. the canonical cards under another
// environment); --fabric --scenes S,... --references R,...: those references as given, the
// fabric only bakes the weave maps (woven, physical-aniso) and gives the weave period for
// --level auto; else --references and --scenes as given.
FitFiles ResolveFitFiles(const FitArgs& a, const Globals& g) {
  FitFiles f;
  if (!a.fabric.empty() && !a.references.empty()) {
    if (a.scenes.empty())
      throw std::invalid_argument("--fabric --references needs --scenes (one card per reference)");
    if (!a.target_error.empty())
      throw std::invalid_argument("--target-error renders references: not with --references");
  }
  if (!a.fabric.empty() && a.references.empty()) {
    if (!a.references2.empty())
      throw std::invalid_argument("--references2 needs --references");
    f.scenes = a.scenes.empty() ? CanonicalScenes() : SplitList(a.scenes);
    if (f.scenes.empty()) throw std::invalid_argument("--scenes: no scene card given");
    std::vector<double> targets;
    for (const std::string& s : f.scenes) {
      targets.push_back(TargetErrorFor(a.target_error, a.fabric, s));
      f.refs.push_back(CachedReference(s, a.fabric, a.spp, 1, g.quiet, 0, targets.back()));
    }
    // The noise floor: from the references' own half-sample channels when every one has them
    // (fit/metrics/reference_halves.h), else (or with --second-seed) from seed-2 renders.
    bool halves = !a.second_seed;
    for (size_t i = 0; halves && i < f.refs.size(); ++i) halves = fit::HasHalfChannels(f.refs[i]);
    if (!a.no_floor && !halves)
      for (size_t i = 0; i < f.scenes.size(); ++i)
        f.refs2.push_back(CachedReference(f.scenes[i], a.fabric, a.spp, 2, g.quiet, 0, targets[i]));
  } else {
    f.refs = SplitList(a.references);
    f.scenes = SplitList(a.scenes);
    f.refs2 = SplitList(a.references2);
    if (f.refs.empty() || f.refs.size() != f.scenes.size())
      throw std::invalid_argument("--references and --scenes need the same number (>= 1) of files");
    if (!f.refs2.empty() && f.refs2.size() != f.refs.size())
      throw std::invalid_argument("--references2 needs one file per reference");
    f.given = true;
  }
  return f;
}

// The model's defaults, with the cloth options from the command line.
render::MaterialPreset StartPreset(const FitArgs& a) {
  render::MaterialPreset start = render::DefaultPreset(render::ParseModelKind(a.model));
  if (start.model == render::ModelKind::kCloth) {
    render::MaterialPreset probe = render::ParsePreset(
        {{"schema", "clothfit.preset"}, {"version", 1}, {"model", "cloth"},
         {"cloth", {{"variant", a.variant}, {"sheen_default", a.sheen_default},
                    {"subsurface", a.subsurface}}},
         {"parameters", nlohmann::json::object()}},
        "command line");
    start.cloth = probe.cloth;
  }
  return start;
}

// The --yarn-lobe settings (session 11), recorded as fit.yarn_lobe_settings for `evaluate`.
fit::YarnLobeSettings YarnLobeSettingsOf(const FitArgs& a) {
  fit::YarnLobeSettings s;
  s.mode = a.yarn_lobe;
  s.fabric = a.fabric.empty() ? std::string() : fs::absolute(a.fabric).lexically_normal().string();
  s.positions = a.yarn_lobe_positions;
  s.nodes = a.yarn_quad_nodes > 0 ? a.yarn_quad_nodes : 16;
  s.table_theta = a.yarn_table_theta;
  s.table_jitter = a.yarn_table_jitter;
  s.ibl = a.yarn_ibl;
  return s;
}

// Everything but the level (which needs the loaded scenes when it is auto).
fit::FitOptions MakeFitOptions(const FitArgs& a, const render::MaterialPreset& start,
                               const FitFiles& files) {
  fit::FitOptions o;
  o.start = start;
  o.locked = SplitList(a.lock);
  fit::ApplyModelDefaults(&o);  // dielectric locks; physical-aniso's locks and start
  o.space = fit::ParseSpace(a.space);
  o.loss = a.loss == "huber" ? fit::Loss::kHuber
           : a.loss == "cauchy" ? fit::Loss::kCauchy
           : a.loss == "none" ? fit::Loss::kNone
           : throw std::invalid_argument("--loss: unknown '" + a.loss + "' (huber, cauchy, none)");
  o.loss_scale = a.loss_scale;
  o.pixel_stride = a.stride;
  o.max_iterations = a.max_iterations;
  o.min_coverage = a.min_coverage;
  o.exact_ibl_samples = a.exact_ibl;
  o.sheen_tilt_degrees = a.sheen_tilt;  // s10-velvet
  ApplyVisibilityFlags(a.visibility, &o);  // s9-vis
  o.ibl_engine = ParseIblEngine(a.ibl_engine);
  if (!a.env_sun.empty()) o.env_sun = render::ParseSunMode(a.env_sun, "--env-sun");  // s10-sun
  o.env_sun_default = render::kCliDefaultSunMode;
  // woven: the IBL mode the previews (and the written preset) use. FIS exists on the three.js
  // engine only (render/preview/preview.h UsesWovenFis).
  if (o.start.model != render::ModelKind::kWoven) {
    if (a.woven_ibl != "auto")
      throw std::invalid_argument("--woven-ibl " + a.woven_ibl + ": only for --model woven");
    if (a.fis_taps >= 0 || a.fis_diffuse_taps >= 0)
      throw std::invalid_argument(std::string(a.fis_taps >= 0 ? "--fis-taps" : "--fis-diffuse-taps") +
                                  ": only for --model woven --woven-ibl fis");
  }
  if (o.start.model == render::ModelKind::kWoven) {
    render::PreviewOptions po;
    po.model = o.start.model;
    po.ibl_engine = o.ibl_engine;
    const bool threejs = render::UsesThreejsIbl(po);
    if (a.woven_ibl == "fis" && !threejs)
      throw std::invalid_argument("--woven-ibl fis: filtered importance sampling needs the "
                                  "three.js IBL engine (--ibl-engine threejs or auto)");
    const woven::IblMode mode = a.woven_ibl == "fis"     ? woven::IblMode::kFis
                                : a.woven_ibl == "split" ? woven::IblMode::kSplit
                                : a.woven_ibl == "bent"  ? woven::IblMode::kBent
                                : threejs                ? kDefaultWovenIbl
                                                         : woven::IblMode::kSplit;
    if (mode != woven::IblMode::kFis && (a.fis_taps >= 0 || a.fis_diffuse_taps >= 0))
      throw std::invalid_argument(std::string(a.fis_taps >= 0 ? "--fis-taps" : "--fis-diffuse-taps") +
                                  ": only with --woven-ibl fis (the default is the split sum)");
    o.start.woven.ibl = a.exact_ibl > 0 ? woven::IblMode::kSplit : mode;
    o.start.woven.fis_taps = a.fis_taps >= 0 ? a.fis_taps : woven::kDefaultFisTaps;
    o.start.woven.fis_diffuse_taps =
        a.fis_diffuse_taps >= 0 ? a.fis_diffuse_taps : woven::kDefaultFisDiffuseTaps;
  }
  // Woven's yarn lobes (session 12): "auto" is the fabric's far-field lobe in the preset when
  // the fabric has yarns (irawan) or is a microcylinder fabric of one hue (sadeghi, session 19),
  // nothing asks for what the lobe cannot do, and (session 25) the references are clothfit's
  // own renders of that fabric: another renderer's yarns need not scatter as our model of the
  // fabric does, so on its images woven keeps its GGX lobes and fits their shape
  // (fit/woven_fit.h, the lobe-shape stage; docs/fitting.md "Woven's lobe shape on another
  // renderer's yarns").
  // The first reference that clothfit did not render from --fabric (ForeignReference), "" when
  // every one was or the fit rendered them itself; read only where it decides something, after
  // the option checks above.
  // The fabric is loaded at most once here (an Irawan BSDF estimates its normalisation when built).
  std::optional<render::Fabric> fabric_memo;
  const auto fabric = [&]() -> const render::Fabric& {
    if (!fabric_memo) fabric_memo = render::LoadFabric(a.fabric);
    return *fabric_memo;
  };
  std::optional<std::string> foreign_memo;
  const auto foreign = [&]() -> const std::string& {
    if (!foreign_memo) {
      foreign_memo = std::string();
      if (!a.fabric.empty() && files.given)
        for (size_t i = 0; i < files.refs.size() && foreign_memo->empty(); ++i)
          *foreign_memo = ForeignReference(files.refs[i], a.fabric, fabric().name);
    }
    return *foreign_memo;
  };
  std::string lobe = a.yarn_lobe;
  const bool lobe_compatible = a.sheen_tilt == 0.0 &&
                               (a.woven_ibl == "auto" || a.woven_ibl == "split");
  if (lobe == "auto") {
    bool has_lobe = false;
    if (o.start.model == render::ModelKind::kWoven && !a.fabric.empty() && lobe_compatible) {
      const std::string m = fabric().model;
      has_lobe = m == "irawan" || (m == "sadeghi" && fit::MicrocylinderRefusal(a.fabric).empty());
    }
    if (has_lobe && !foreign().empty())
      std::printf("fit: yarn lobe: woven's GGX lobes, shape fitted, not the fabric's far-field "
                  "lobe: %s (--yarn-lobe preset forces it)\n", foreign().c_str());
    lobe = has_lobe && foreign().empty() ? "preset" : "none";
  }
  // Another renderer's references with the GGX lobes and an irawan fabric's weave maps (whatever
  // chose those lobes): the warp/weft balance is held where the maps were baked (the start
  // preset's warp_share). Measured, a free share runs to 0 or 1 on such references and switches
  // off the texels of one yarn (docs/fitting.md "Woven's lobe shape on another renderer's yarns").
  if (o.start.model == render::ModelKind::kWoven && lobe == "none" && a.weave_maps != "none" &&
      !a.fabric.empty() && files.given && fabric().model == "irawan" &&
      !foreign().empty()) {
    if (std::find(o.locked.begin(), o.locked.end(), "warp_share") == o.locked.end())
      o.locked.push_back("warp_share");
    std::printf("fit: warp_share held at %g with the weave maps: %s\n",
                o.start.values[size_t(o.start.Offset("warp_share"))], foreign().c_str());
  }
  if (lobe == "preset") {  // docs/fitting.md "The far-field yarn lobe"
    if (o.start.model != render::ModelKind::kWoven)
      throw std::invalid_argument("--yarn-lobe preset: only for --model woven");
    if (a.fabric.empty())
      throw std::invalid_argument("--yarn-lobe preset: needs --fabric (an irawan or sadeghi fabric)");
    if (!lobe_compatible)
      throw std::invalid_argument("--yarn-lobe preset: not with --sheen-tilt or --woven-ibl "
                                  "fis|bent (the lobe has its own split sum)");
    fit::YarnLobeSettings s = YarnLobeSettingsOf(a);
    s.mode = "quadrature";
    // 8 nodes: the fits match 16's (canvas 0.009795 vs 0.009817, twill 0.01672 vs 0.01668;
    // docs/fitting.md) at half the shader's per-light cost
    s.nodes = a.yarn_quad_nodes > 0 ? a.yarn_quad_nodes : 8;
    s.fabric = a.fabric;  // as given: the preset records it (informative), no machine paths
    const std::string line = fit::ApplyPresetYarnLobe(s, &o);
    std::printf("fit: %s\n", line.c_str());
  } else if (lobe != "none") {  // session 11 measurement (docs/fitting.md "far-field yarn lobe")
    if (o.start.model != render::ModelKind::kWoven)
      throw std::invalid_argument("--yarn-lobe: only for --model woven");
    if (a.yarn_lobe == "farfield" && a.exact_ibl <= 0)
      throw std::invalid_argument("--yarn-lobe farfield: needs --exact-ibl N (the lobe has no "
                                  "split-sum path; --yarn-lobe table has)");
    if (a.fabric.empty())
      throw std::invalid_argument("--yarn-lobe " + a.yarn_lobe + ": needs --fabric (an irawan fabric)");
    if (a.sheen_tilt != 0.0 || a.visibility.ao || a.visibility.indirect)
      throw std::invalid_argument("--yarn-lobe " + a.yarn_lobe + ": not with --sheen-tilt, --ao "
                                  "or --indirect");
    if (a.yarn_lobe == "farfield-split" && a.exact_ibl > 0)
      throw std::invalid_argument("--yarn-lobe farfield-split: the table's split sum is not used "
                                  "with --exact-ibl (use --yarn-lobe farfield)");
    const std::string line = fit::ApplyYarnLobe(YarnLobeSettingsOf(a), &o);
    if (!line.empty()) std::printf("fit: %s\n", line.c_str());
  }
  ApplyStarts(a, &o);
  if (a.no_cloth_basin && o.start.model != render::ModelKind::kWoven)
    throw std::invalid_argument("--no-cloth-basin: only for --model woven");
  o.cloth_basin_start = !a.no_cloth_basin;
  return o;
}

// The scenes, their environments (each distinct one loaded once) and references, by index.
struct LoadedScenes {
  std::vector<render::Scene> sc;
  std::vector<std::shared_ptr<render::Environment>> envs;
  std::vector<fit::Reference> rr, rr2;
};

// --scenes takes scene cards; a glTF (the card's `gltf` field) passed in their place is named
// as such instead of failing on its first field ("unknown field 'accessors'").
void CheckIsSceneCard(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
  bool gltf = ext == ".gltf" || ext == ".glb";
  if (!gltf && ext == ".json") {
    std::ifstream in(path);
    std::string head(4096, '\0');
    in.read(head.data(), long(head.size()));
    head.resize(size_t(in.gcount()));
    gltf = head.find("\"asset\"") != std::string::npos &&
           head.find("\"gltf\"") == std::string::npos;
  }
  if (gltf)
    throw std::runtime_error(path + ": this is a glTF file, not a clothfit scene card: --scenes "
                             "takes scene cards (docs/scene-card.md), which name their glTF in "
                             "the `gltf` field (e.g. datasets/scenes/sphere.json)");
}

LoadedScenes LoadFitScenes(const FitFiles& f, const fit::ReferenceOptions& ro) {
  LoadedScenes l;
  for (const std::string& s : f.scenes) CheckIsSceneCard(s);
  // Loaded once per process (a --batch runs many fits; the key names the file and its
  // intensity and rotation, which is all LoadSceneEnvironment reads from the card).
  static std::map<std::string, std::shared_ptr<render::Environment>> env_by_key;
  for (size_t i = 0; i < f.scenes.size(); ++i) {
    l.sc.push_back(render::LoadScene(f.scenes[i]));
    const auto& spec = l.sc.back().card.environment;
    const std::string key = spec ? spec->path + "|" + std::to_string(spec->intensity) + "|" +
                                       std::to_string(spec->rotation_y)
                                 : std::string();
    if (key.empty()) {
      l.envs.push_back(nullptr);
    } else {
      auto it = env_by_key.find(key);
      if (it == env_by_key.end())
        it = env_by_key.emplace(key, LoadSceneEnvironment(l.sc.back(), true)).first;
      l.envs.push_back(it->second);
    }
    l.rr.push_back(fit::ReadReference(f.refs[i], ro));
    if (!f.refs2.empty()) l.rr2.push_back(fit::ReadReference(f.refs2[i], ro));
  }
  return l;
}

// A scene's noise floor above the fit's error (session 27). The floor is one reference's own
// noise, which no fit can beat (a fit's squared error is about the floor's square plus the
// model's error), so a floor well above the error is not the reference's noise: e.g.
// --references2 of another material or scene. From 1.5x: a sound floor exceeds the error only
// by what the fit's parameters absorb of the noise and by the floor's own sampling error, a
// few percent over the blocks of a scene.
constexpr double kImplausibleFloorRatio = 1.5;
bool ImplausibleNoiseFloor(const fit::SceneError& e) {
  return e.noise_floor >= 0.0 && e.noise_floor > kImplausibleFloorRatio * e.rmse;
}

// The "fit" record of the preset: settings, solver outcome and, per scene, what
// `clothfit report` needs.
nlohmann::json FitRecord(const FitArgs& a, const fit::FitOptions& o, const fit::FitResult& res,
                         const FitFiles& f, const LoadedScenes& l) {
  nlohmann::json fitj;
  fitj["space"] = fit::ToString(o.space);
  fitj["loss"] = a.loss;
  fitj["loss_scale"] = o.loss_scale;
  fitj["level"] = o.level;
  fitj["block_pixels"] = 1 << o.level;
  fitj["pixel_stride"] = o.pixel_stride > 0 ? o.pixel_stride : std::max(1, (1 << o.level) / 4);
  fitj["locked"] = o.locked;
  fitj["final_cost"] = res.final_cost;
  fitj["initial_cost"] = res.initial_cost;
  fitj["iterations"] = res.iterations;
  fitj["starts"] = res.starts;
  if (o.start.model == render::ModelKind::kWoven)
    fitj["cloth_basin_start"] = fit::UsesClothBasinStart(o);  // session 13
  if (!res.candidates.empty()) {
    nlohmann::json cj = nlohmann::json::array();
    for (const auto& c : res.candidates)
      cj.push_back({{"path", c.name}, {"rmse", c.rmse}, {"iterations", c.iterations},
                    {"seconds", c.seconds}});
    fitj["woven_paths"] = cj;
  }
  fitj["seconds"] = res.seconds;
  fitj["setup_seconds"] = res.setup_seconds;
  fitj["termination"] = res.termination;
  fitj["converged"] = res.converged;
  fitj["max_iterations"] = o.max_iterations;
  fitj["min_coverage"] = o.min_coverage;
  if (o.exact_ibl_samples > 0) fitj["exact_ibl_samples"] = o.exact_ibl_samples;  // not an engine fit
  if (o.yarn_far_field) {  // session 11 measurement: not an engine fit either
    fitj["yarn_lobe"] = (o.yarn_quadrature_nodes > 0
                             ? "quadrature (" + std::to_string(o.yarn_quadrature_nodes) + " nodes) + "
                             : std::string()) +
                        (o.yarn_table ? std::string(o.yarn_table_ibl_only ? "split sum of the " : "") +
                                            "table " + std::to_string(o.yarn_table->n_theta) + "x" +
                                            std::to_string(o.yarn_table->n_phi) + " of the "
                                      : std::string()) +
                        o.yarn_far_field->Describe();
    fitj["yarn_lobe_warp_albedo_share"] = o.yarn_far_field->WarpAlbedoShare();
    fitj["yarn_lobe_settings"] = fit::ToJson(YarnLobeSettingsOf(a));
  }
  if (o.sheen_tilt_degrees != 0.0) fitj["sheen_tilt_degrees"] = o.sheen_tilt_degrees;  // s10-velvet
  if (o.shadows || o.visibility.enabled()) fitj["visibility"] = VisibilityJson(o);  // s9-vis
  fitj["card_visibility"] = o.card_visibility;  // session 13: the cards' "visibility" applied
  if (res.albedo_pass)  // the light map's second pass baked with the first pass's albedo
    fitj["light_map_albedo_pass"] = true;
  {  // the IBL engine the previews reproduced (resolved; `evaluate` defaults to it)
    render::PreviewOptions po;
    po.model = o.start.model;
    po.cloth = o.start.cloth;
    po.ibl_engine = o.ibl_engine;
    fitj["ibl_engine"] = render::UsesThreejsIbl(po) ? "threejs" : "filament";
  }
  // s10-sun (docs/sun.md): the flag's mode, or "card" (each card's environment.sun, else auto).
  fitj["env_sun"] = o.env_sun ? render::SunModeName(*o.env_sun) : "card";
  nlohmann::json ab = nlohmann::json::array();
  bool flagged_bound = false;
  for (const fit::AtBound& b : res.at_bound) {
    ab.push_back({{"name", b.name}, {"value", b.value}, {"bound", b.upper ? "upper" : "lower"},
                  {"flagged", b.flagged}});
    flagged_bound = flagged_bound || b.flagged;
  }
  fitj["at_bound"] = ab;
  std::string why;  // free parameters without effect at the solution (session 27)
  const std::vector<std::string> none = fit::ParametersWithoutEffect(res.preset, o, &why);
  if (!none.empty()) fitj["no_effect"] = {{"parameters", none}, {"why", why}};
  fitj["status"] = !res.converged ? "not converged" : flagged_bound ? "at bound" : "ok";
  fitj["solver"] = res.solver_report;
  fitj["rmse"] = res.rmse;
  nlohmann::json sj = nlohmann::json::array();
  for (size_t i = 0; i < res.scenes.size(); ++i) {
    const auto& e = res.scenes[i];
    nlohmann::json x = {{"scene", e.scene}, {"reference", e.reference}, {"blocks", e.blocks},
                        {"blocks_dropped_preview", e.dropped_preview},
                        {"blocks_dropped_coverage", e.dropped_coverage},
                        {"rmse", e.rmse}};
    if (e.noise_floor >= 0) {
      x["noise_floor"] = e.noise_floor;
      x["noise_floor_source"] = e.noise_floor_source;
      if (ImplausibleNoiseFloor(e)) x["noise_floor_suspect"] = true;  // WarnImplausibleNoiseFloors
    }
    // What `clothfit report` needs: the second-seed reference (noise floor), the display
    // transform of the scene card, and the linear fitted preview written below.
    x["reference"] = fs::absolute(e.reference).lexically_normal().string();
    if (i < f.refs2.size()) x["reference2"] = fs::absolute(f.refs2[i]).lexically_normal().string();
    if (i < l.sc.size()) {
      x["tone_mapping"] = l.sc[i].card.tone_mapping;
      x["exposure"] = l.sc[i].card.exposure;
      if (!a.images.empty())
        x["preview"] = fs::absolute(fs::path(a.images) /
                                    (fs::path(f.scenes[i]).stem().string() + "_preview.exr"))
                           .lexically_normal()
                           .string();
    }
    sj.push_back(x);
  }
  fitj["scenes"] = sj;
  return fitj;
}

// Per scene: the fitted preview (display PNG and linear EXR) and the residual EXR.
void WriteFitImages(const std::string& dir, const FitFiles& f, const LoadedScenes& l,
                    const render::MaterialPreset& preset, const fit::FitOptions& o) {
  fs::create_directories(dir);
  for (size_t i = 0; i < l.sc.size(); ++i) {
    const render::Scene& scene = l.sc[i];
    // the fit's own preview settings: a measurement fit's (exact IBL, visibility, sheen tilt,
    // far-field lobe) images show what its residuals were computed on
    std::vector<float> frame = fit::RenderPreviewFrame(scene, l.envs[i].get(), preset, o);
    // A transparent-film reference (alpha coverage) has no environment behind the geometry:
    // where it saw nothing, the preview images show nothing either, so side-by-sides and
    // residuals do not mix in background differences.
    if (l.rr[i].layout.find("alpha") != std::string::npos)
      for (size_t p = 0; p < l.rr[i].fabric.size(); ++p)
        if (l.rr[i].fabric[p] <= 0.f)
          for (size_t c = 0; c < 3; ++c) frame[p * 3 + c] = 0.f;
    const std::string stem = fs::path(f.scenes[i]).stem().string();
    const auto op = render::ParseToneMapping(scene.card.tone_mapping);
    io::WritePng8((fs::path(dir) / (stem + "_preview.png")).string(), scene.card.width,
                  scene.card.height, ToDisplayImage(frame, op, scene.card.exposure));
    io::Image prev_img;
    prev_img.width = scene.card.width;
    prev_img.height = scene.card.height;
    prev_img.channel_names = {"R", "G", "B"};
    prev_img.pixels = frame;
    prev_img.metadata["clothfit:preview"] = "fitted preview, linear radiance (un-tonemapped)";
    prev_img.metadata["clothfit:scene"] = f.scenes[i];
    io::WriteExr((fs::path(dir) / (stem + "_preview.exr")).string(), prev_img);
    io::Image res_img;
    res_img.width = scene.card.width;
    res_img.height = scene.card.height;
    res_img.channel_names = {"R", "G", "B"};
    res_img.pixels.resize(frame.size());
    for (size_t k = 0; k < frame.size(); ++k) res_img.pixels[k] = frame[k] - l.rr[i].rgb[k];
    res_img.metadata["clothfit:residual"] = "preview - reference, linear radiance";
    io::WriteExr((fs::path(dir) / (stem + "_residual.exr")).string(), res_img);
  }
}

// The one-line result on stdout.
void PrintFitSummary(const FitArgs& a, const fit::FitOptions& o, const fit::FitResult& res,
                     const render::MaterialPreset& preset) {
  double floor = 0.0;
  int nf = 0;
  for (const auto& e : res.scenes)
    if (e.noise_floor >= 0) {
      floor += e.noise_floor;
      ++nf;
    }
  std::printf("fit: %s %s: rmse %.4f (%s)%s, cost %.4g, %d iterations over %d starts, "
              "%.2f s -> %s\n",
              a.fabric.empty() ? a.references.c_str() : a.fabric.c_str(),
              render::ToString(preset.model).c_str(), res.rmse, fit::ToString(o.space).c_str(),
              nf ? (", noise floor " + std::to_string(floor / nf).substr(0, 6)).c_str() : "",
              res.final_cost, res.iterations, res.starts, res.seconds, a.out.c_str());
  for (const auto& e : res.scenes)
    std::printf("fit:   %s: %d blocks kept, %d dropped (%d not all fabric in the preview, %d "
                "coverage < %.2f)\n",
                fs::path(e.scene).filename().string().c_str(), e.blocks,
                e.dropped_preview + e.dropped_coverage, e.dropped_preview, e.dropped_coverage,
                o.min_coverage);
}

// A WARNING line per scene whose floor is implausible (the exit status is unchanged: the fit
// itself is not in question, its noise floor is).
void WarnImplausibleNoiseFloors(const fit::FitResult& res, const FitFiles& f) {
  for (size_t i = 0; i < res.scenes.size(); ++i) {
    const fit::SceneError& e = res.scenes[i];
    if (!ImplausibleNoiseFloor(e)) continue;
    const std::string why =
        e.noise_floor_source == "second reference" && i < f.refs2.size()
            ? f.refs2[i] + " and " + e.reference +
                  " do not look like two renders (seeds) of the same material and scene"
            : e.reference + "'s half channels do not look like two halves of its image";
    std::printf("fit: WARNING: %s: noise floor %.4f is above the fit's rmse %.4f; a fit cannot "
                "beat its reference's own noise, so the floor looks wrong: %s\n",
                fs::path(e.scene).filename().string().c_str(), e.noise_floor, e.rmse,
                why.c_str());
  }
}

// Convergence (docs/references.md): 3 when the fit did not converge or stopped at a
// degenerate bound (the preset is written and flagged), else 0; says why on stdout. Parameters
// without effect at the solution (fit::ParametersWithoutEffect) get a note and no flag.
int ConvergenceStatus(const fit::FitOptions& o, const fit::FitResult& res) {
  int status = 0;
  std::string why;
  const std::vector<std::string> none = fit::ParametersWithoutEffect(res.preset, o, &why);
  if (!none.empty()) {
    std::string names;
    for (const std::string& n : none) names += (names.empty() ? "" : ", ") + n;
    std::printf("fit: note: %s: no effect %s (both yarn lobes are one isotropic GGX lobe; "
                "their values are arbitrary and a bound on them is not flagged)\n",
                names.c_str(), why.c_str());
  }
  if (!res.converged) {
    std::printf("fit: WARNING: not converged (%s; --max-iterations %d per start)\n",
                res.termination.c_str(), o.max_iterations);
    status = 3;
  }
  for (const fit::AtBound& b : res.at_bound) {
    if (!b.flagged) continue;
    std::printf("fit: WARNING: %s at its %s bound (%g)\n", b.name.c_str(),
                b.upper ? "upper" : "lower", b.value);
    status = 3;
  }
  return status;
}

// The block level: --level; else from the weave period (--weave-period through each card's
// uv_metres_per_unit, or the fabric's); else 4 (docs/references.md). Printed with the reason.
int ChooseLevel(const FitArgs& a, int fixed_level, double fabric_period,
                const std::vector<fit::SceneInput>& inputs, const FitFiles& f) {
  int level = 4;
  std::string why = "weave period unknown (--weave-period): default";
  if (a.level != "auto") {
    level = fixed_level;
    why = "--level";
  } else if (!a.weave_period.empty()) {
    const fit::WeavePeriod period = fit::ParseWeavePeriod(a.weave_period);
    level = 1;
    for (size_t i = 0; i < inputs.size(); ++i)
      level = std::max(level, fit::AutoLevel(*inputs[i].scene,
                                             fit::WeavePeriodUv(period, *inputs[i].scene, f.scenes[i])));
    why = "auto, weave period " + a.weave_period;
  } else if (fabric_period > 0.0) {
    level = fit::AutoLevel(inputs, fabric_period);
    why = "auto, weave period from the fabric";
  }
  std::printf("fit: level %d (%d px blocks; %s)\n", level, 1 << level, why.c_str());
  return level;
}

// Filament's subsurface cloth (MATERIAL_HAS_SUBSURFACE_COLOR) replaces the Lambert term by a
// wrapped diffuse, W(n.l, 0.5) sat(subsurface + n.l), rather than adding to it (brdf/cloth.h), so
// `--subsurface` can fit worse than plain cloth. The same fit without it is run as a check; when
// it is better, stdout says so (the preset stays the subsurface fit that was asked for) and the
// preset records both errors in fit.subsurface_check.
void CheckSubsurfaceAgainstPlain(const std::vector<fit::SceneInput>& inputs,
                                 const fit::FitOptions& o, const fit::FitResult& res,
                                 render::MaterialPreset& preset) {
  fit::FitOptions plain = o;
  plain.start.cloth.subsurface = false;
  fit::FitResult p;
  try {
    p = fit::FitImages(inputs, plain);
  } catch (const fit::FitError&) {
    return;
  }
  if (!p.usable) return;
  preset.extra["fit"]["subsurface_check"] = {{"rmse_with_subsurface", res.rmse},
                                             {"rmse_without_subsurface", p.rmse},
                                             {"worse", p.rmse < res.rmse}};
  if (p.rmse < res.rmse)
    std::printf("fit: WARNING: --subsurface fits worse than plain cloth (rmse %.4f vs %.4f): "
                "Filament's subsurface replaces the Lambert term by wrapped diffuse; drop "
                "--subsurface for the better fit\n", res.rmse, p.rmse);
}

// Whether `path` is `dir` or lies below it (lexically, after making both absolute).
bool IsWithin(const fs::path& path, const fs::path& dir) {
  if (dir.empty()) return true;  // the working directory exists
  const fs::path rel =
      fs::absolute(path).lexically_normal().lexically_relative(fs::absolute(dir).lexically_normal());
  return !rel.empty() && *rel.begin() != "..";
}

// The fit's outputs against its inputs and the file system, before any work (session 27): no
// output is one of the inputs (before, `--fabric canvas.json --out canvas.json` replaced the
// fabric by the preset), and each output's directory takes new files (before, an unwritable
// --out failed only after the whole fit). Outputs: --out, the weave maps written next to it
// (woven and physical-aniso with --fabric; woven's glint map) and the --images files; inputs:
// --fabric and every file of --references, --references2 and --scenes.
void CheckFitOutputs(const FitArgs& a) {
  std::vector<NamedPath> inputs;
  if (!a.fabric.empty()) inputs.push_back({"--fabric", a.fabric});
  const std::pair<std::string, std::string> lists[] = {
      {"--references", a.references}, {"--references2", a.references2}, {"--scenes", a.scenes}};
  for (const auto& [flag, list] : lists)
    for (const std::string& path : SplitList(list)) inputs.push_back({flag, path});
  std::vector<NamedPath> outputs = {{"--out", a.out}};
  if ((a.model == "woven" || a.model == "physical-aniso") && !a.fabric.empty() &&
      a.weave_maps != "none")
    outputs.push_back({"--out's weave maps", (fs::path(a.out).parent_path() /
                                              (fs::path(a.out).stem().string() + ".weave.exr"))
                                                 .string()});
  // Woven's --weave-maps glint also writes the glint map (fit/woven_fit.cpp AttachWeaveMaps;
  // session 28: before, it was not checked and could replace an input).
  if (a.model == "woven" && !a.fabric.empty() && a.weave_maps == "glint")
    outputs.push_back({"--out's glint map", (fs::path(a.out).parent_path() /
                                             (fs::path(a.out).stem().string() + ".glint.exr"))
                                                .string()});
  if (!a.images.empty()) {
    const std::vector<std::string> scenes =
        a.scenes.empty() ? CanonicalScenes() : SplitList(a.scenes);
    for (const std::string& scene : scenes)
      for (const char* suffix : {"_preview.png", "_preview.exr", "_residual.exr"})
        outputs.push_back({"--images", (fs::path(a.images) /
                                        (fs::path(scene).stem().string() + suffix)).string()});
  }
  for (const NamedPath& out : outputs) RefuseOutputOverInput(out, inputs);
  RequireWritableOutput(a.out, "--out");
  if (!a.images.empty()) RequireWritableDirectory(a.images, "--images");
}

// `clothfit fit` after parsing: returns the exit status (throws on bad input).
int RunFit(const FitArgs& a, const Globals& g) {
  // Where the results go, before any work: --out's directory must exist, unless --images (created
  // when the images are written, before the preset) is that directory or lies below it, as in
  // `--images out/x --out out/x.json`; no output may be an input, and the directories must take
  // new files (CheckFitOutputs).
  if (a.images.empty() || !IsWithin(a.images, fs::path(a.out).parent_path()))
    io::RequireOutputDirectory(a.out);
  CheckFitOutputs(a);
  std::unique_ptr<tbb::global_control> limit;
  if (a.threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  size_t(a.threads));
  const int fixed_level = ParseFixedLevel(a.level);
  const double weave_period = a.fabric.empty() ? 0.0 : render::LoadFabric(a.fabric).weave_period_uv;
  const FitFiles files = ResolveFitFiles(a, g);
  fit::FitOptions o = MakeFitOptions(a, StartPreset(a), files);
  // woven: starts 0.6 and 0.3 unless --starts says otherwise: measured, a 0.9 start changed
  // no fabric's block RMSE beyond 0.0002 (docs/fitting.md, "Fit speed"), and 0.3 (session 26)
  // finds the glossy basin 0.6 misses on other renderers' references (docs/fitting.md "A
  // start for glossy references"). With the fabric's far-field lobe the roughness is locked
  // and the two starts are one. Since session 13 the cloth-basin start runs besides them
  // (fit/woven_fit.h; --no-cloth-basin).
  if (o.start.model == render::ModelKind::kWoven && a.starts.empty() && a.start_values.empty())
    o.start_roughness = {0.6, 0.3};
  if (o.start.model == render::ModelKind::kWoven && !a.fabric.empty() && a.weave_maps != "none") {
    const std::string maps = (fs::path(a.out).parent_path() /
                              (fs::path(a.out).stem().string() + ".weave.exr")).string();
    fit::WeaveBakeOptions bake;
    bake.indicator = a.weave_maps == "indicator";
    bake.relief = a.weave_maps == "relief";
    bake.glint = a.weave_maps == "glint";
    bake.view_band = a.weave_map_view_band;
    // View bands (session 14) with the default maps, unless turned off or one band is measured.
    bake.view_bands = a.weave_maps == "auto" && !a.no_weave_map_views && a.weave_map_view_band < 0;
    const std::string line = fit::AttachWeaveMaps(a.fabric, maps, &o, bake);
    if (!line.empty()) std::printf("fit: %s\n", line.c_str());
  }
  // physical-aniso: the SAME maps the woven fit bakes (woven defaults as the start lobes), as
  // a colour map and an anisotropy map (render/preview/preview.cpp, AnisoFromWeave).
  if (o.start.model == render::ModelKind::kPhysicalAniso && !a.fabric.empty() &&
      a.weave_maps != "none") {
    const std::string maps = (fs::path(a.out).parent_path() /
                              (fs::path(a.out).stem().string() + ".weave.exr")).string();
    const std::string line = fit::AttachWeaveMapsToPhysicalAniso(a.fabric, maps, &o);
    if (!line.empty()) std::printf("fit: %s\n", line.c_str());
  }
  // The maps' filter (both models' maps alike: the issue's "same maps" rule).
  if (!fit::SetMapAnisotropy(a.map_anisotropy >= 0 ? a.map_anisotropy : fit::kDefaultMapAnisotropy,
                             &o) &&
      a.map_anisotropy >= 0)
    throw std::invalid_argument("--map-anisotropy: this fit has no weave maps (woven or "
                                "physical-aniso with an Irawan --fabric, --weave-maps not none)");
  // Load everything.
  fit::ReferenceOptions ro;
  ro.alpha = fit::ParseAlphaMode(a.alpha);
  ro.coverage_channel = a.coverage_channel;
  ro.noise = fit::ParseNoiseMode(a.noise);
  if (!a.weave_period.empty()) (void)fit::ParseWeavePeriod(a.weave_period);  // before any work
  const LoadedScenes l = LoadFitScenes(files, ro);
  std::vector<fit::SceneInput> inputs;
  for (size_t i = 0; i < l.sc.size(); ++i)
    inputs.push_back({&l.sc[i], l.envs[i].get(), &l.rr[i], l.rr2.empty() ? nullptr : &l.rr2[i],
                      files.scenes[i]});
  o.level = ChooseLevel(a, fixed_level, weave_period, inputs, files);
  for (size_t i = 0; i < l.rr.size(); ++i)
    std::printf("fit: %s: %s; noise: %s\n", files.refs[i].c_str(), l.rr[i].layout.c_str(),
                l.rr[i].noise.c_str());
  // Every parameter locked (session 27): nothing to fit. Not an error (a preset's error at its
  // own values, as `clothfit evaluate` measures it), but said: before, "0 iterations", status ok.
  const bool nothing_fitted = fit::FreeParameterCount(o) == 0;
  if (nothing_fitted) {
    std::vector<std::string> names;  // --lock and the model's own locks, each once
    for (const std::string& n : o.locked)
      if (std::find(names.begin(), names.end(), n) == names.end()) names.push_back(n);
    std::string locked;
    for (const std::string& n : names) locked += (locked.empty() ? "" : ",") + n;
    std::printf("fit: WARNING: nothing to fit: every parameter of %s is locked (%s: --lock and "
                "the model's own locks); the preset is written at the start values, with their "
                "error\n",
                render::ToString(o.start.model).c_str(), locked.c_str());
  }
  // the light map's second pass (the cards' "visibility", session 13) around the model's fit
  const fit::FitResult res = fit::FitWithLightMapAlbedo(
      inputs, o, [&](const fit::FitOptions& opt, const fit::PreparedScenes* prepared) {
        return opt.start.model == render::ModelKind::kWoven
                   ? fit::FitWovenImages(inputs, opt, prepared)
                   : fit::FitImages(inputs, opt, prepared);
      });
  if (!res.usable) {
    std::fprintf(stderr, "clothfit fit: error: the fit failed (%s); no preset written\n",
                 res.message.c_str());
    return 2;
  }
  render::MaterialPreset preset = res.preset;
  preset.extra["fit"] = FitRecord(a, o, res, files, l);
  if (nothing_fitted) preset.extra["fit"]["nothing_fitted"] = true;
  if (o.start.model == render::ModelKind::kCloth && o.start.cloth.subsurface)
    CheckSubsurfaceAgainstPlain(inputs, o, res, preset);
  preset.extra["provenance"] = {{"tool", "clothfit 0.1.0"},
                                {"fabric", a.fabric.empty() ? nlohmann::json(nullptr)
                                                            : nlohmann::json(a.fabric)}};
  // Images first, the preset last: a preset on disk means its images are complete.
  if (!a.images.empty()) WriteFitImages(a.images, files, l, preset, o);
  // weave_maps: "uri" (relative to the preset; the maps are written next to it) beside the
  // absolute "file", so the preset's directory can move (docs/preset-format.md).
  render::AddPresetWeaveMapUris(&preset, a.out);
  render::WritePreset(a.out, preset);
  PrintFitSummary(a, o, res, preset);
  WarnImplausibleNoiseFloors(res, files);
  return ConvergenceStatus(o, res);
}

}  // namespace

namespace {

// One fit, as `clothfit fit` runs it: the exit status (errors printed, never thrown).
int RunFitReporting(const FitArgs& a, const Globals& g) {
  try {
    return RunFit(a, g);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "clothfit fit: error: %s\n", e.what());
    return 1;
  }
}

// --batch FILE: one fit per non-empty line (the same options as `clothfit fit`, separated by
// whitespace; no quoting, so no spaces in paths; '#' starts a comment line), run one after the
// other in this process, so the process start-up (dynamic linking), the HDR environments and
// their prefiltered chains are paid once (docs/fitting.md, "Demo pipeline (session 6)"). After
// each job: "fit: batch job N: exit S" on stdout. Returns 0 when every job returned 0 or 3
// (3 when some returned 3), else the first other status.
int RunFitBatch(const std::string& list, const Globals& g) {
  std::ifstream in(list);
  if (!in) throw std::runtime_error(list + ": cannot read the --batch file");
  std::vector<std::vector<std::string>> jobs;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    std::istringstream words(line);
    std::vector<std::string> args;
    for (std::string w; words >> w;) args.push_back(w);
    if (args.empty() || args[0][0] == '#') continue;
    for (const std::string& w : args)
      if (w.find_first_of("\"'\\") != std::string::npos || w == "--batch")
        throw std::runtime_error(list + ": line " + std::to_string(n) +
                                 ": quotes, backslashes and --batch are not allowed in a batch");
    jobs.push_back(args);
  }
  int result = 0;
  for (size_t j = 0; j < jobs.size(); ++j) {
    FitArgs a;
    CLI::App app("clothfit fit (batch job)");
    AddFitOptions(&app, a);
    // -q/--quiet is accepted on a job's line too, as after `clothfit fit` (session 27): that
    // job runs quietly; the process's own -q still silences every job.
    bool job_quiet = false;
    app.add_flag("-q,--quiet", job_quiet, "no progress output on stderr for this job");
    std::vector<std::string> rev(jobs[j].rbegin(), jobs[j].rend());  // CLI11 takes them reversed
    int status = 0;
    try {
      app.parse(rev);
    } catch (const CLI::ParseError& e) {
      std::fprintf(stderr, "clothfit fit: error: %s: job %zu: %s\n", list.c_str(), j + 1,
                   limits::EscapeForMessage(e.what(), 300).c_str());
      status = 1;
    }
    Globals job_globals = g;
    job_globals.quiet = g.quiet || job_quiet;
    if (status == 0) status = RunFitReporting(a, job_globals);
    std::printf("fit: batch job %zu: exit %d\n", j + 1, status);
    std::fflush(stdout);
    if (status == 3 && result == 0) result = 3;
    if (status != 0 && status != 3 && (result == 0 || result == 3)) result = status;
  }
  return result;
}

}  // namespace

void AddFitCommand(CLI::App& app, const Globals& g, int& exit_code) {
  auto a = std::make_shared<FitArgs>();
  auto batch = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand(
      "fit", "fit a material preset so the real-time preview matches the references");
  AddFitOptions(cmd, *a);
  cmd->get_option("--out")->required(false);  // checked below (not with --batch)
  cmd->add_option("--batch", *batch,
                  "run the fits listed in FILE (one line of fit options each) in this process, "
                  "in order; the other options must be absent");
  cmd->callback([a, batch, cmd, &g, &exit_code]() {
    if (!batch->empty()) {
      bool others = false;
      for (const CLI::Option* opt : cmd->get_options())
        others = others || (opt->get_name() != "--batch" && opt->count() > 0);
      if (others) {
        std::fprintf(stderr, "clothfit fit: error: --batch takes no other fit options\n");
        exit_code = 1;
        return;
      }
      try {
        exit_code = RunFitBatch(*batch, g);
      } catch (const std::exception& e) {
        std::fprintf(stderr, "clothfit fit: error: %s\n", e.what());
        exit_code = 1;
      }
      return;
    }
    if (a->out.empty()) {
      std::fprintf(stderr, "clothfit fit: error: --out is required\n");
      exit_code = 1;
      return;
    }
    exit_code = RunFitReporting(*a, g);
  });
}

}  // namespace clothfit::cli
