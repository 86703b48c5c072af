// clothfit render-preview: what the real-time engine draws for a scene and a material preset.
// Also `clothfit tonemap`, and the output checks that fit, render-preview and tonemap share.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>

#include "bin/commands.h"
#include "render/scene/image_io.h"
#include "render/scene/material.h"
#include "render/preview/preview.h"
#include "render/preview/weave_maps.h"
#include "render/scene/sun.h"
#include "render/scene/tonemap.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {

std::vector<float> ToDisplayImage(const std::vector<float>& linear, render::ToneMapping op,
                                  double exposure) {
  std::vector<float> out(linear.size());
  for (size_t i = 0; i + 2 < linear.size(); i += 3) {
    const Rgb<double> c{double(linear[i]), double(linear[i + 1]), double(linear[i + 2])};
    const Rgb<double> d = render::ToDisplay(c, op, exposure);
    for (int k = 0; k < 3; ++k) out[i + size_t(k)] = float(d[k]);
  }
  return out;
}

namespace {
namespace fs = std::filesystem;

// Whether two command-line paths name the same file (RefuseOutputOverInput).
bool SameFile(const std::string& a, const std::string& b) {
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) {
    const bool same = fs::equivalent(a, b, ec);
    if (!ec) return same;
  }
  // Absolute first: weakly_canonical leaves a relative path whose first element does not exist
  // relative ("a.exr" stayed "a.exr" while "./a.exr" became "/cwd/a.exr"; session 28), so two
  // spellings of one new file compared unequal.
  const auto canonical = [](const std::string& p) {
    std::error_code e;
    const fs::path abs = fs::absolute(p, e);
    if (e) return fs::path(p).lexically_normal();
    const fs::path c = fs::weakly_canonical(abs, e);
    return e ? abs.lexically_normal() : c;
  };
  return canonical(a) == canonical(b);
}

// The directory itself if it exists, else its nearest existing ancestor ("." for a relative
// path with none).
fs::path NearestExisting(const fs::path& dir) {
  std::error_code ec;
  fs::path p = dir.empty() ? fs::path(".") : dir;
  while (!fs::exists(p, ec)) {
    const fs::path up = p.parent_path();
    if (up.empty() || up == p) return fs::path(".");
    p = up;
  }
  return p;
}

// Creates and removes a file in `dir`; the error text (strerror) when it cannot, else "".
std::string ProbeWrite(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return "not a directory";
  for (int attempt = 0; attempt < 8; ++attempt) {
    const fs::path probe = dir / (".clothfit-write-probe." + std::to_string(::getpid()) + "." +
                                  std::to_string(attempt));
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0) {
      if (errno == EEXIST) continue;  // another probe of this process id: try the next name
      return std::strerror(errno);
    }
    ::close(fd);
    ::unlink(probe.c_str());
    return "";
  }
  return "cannot create a file in it";
}

void RequireWritableIn(const fs::path& dir, const std::string& flag, const std::string& path) {
  const fs::path d = NearestExisting(dir);
  const std::string why = ProbeWrite(d);
  if (!why.empty())
    throw io::IoError(flag + ": " + path + ": output directory " + d.string() +
                      " is not writable (" + why + ")");
}

}  // namespace

void RefuseOutputOverInput(const NamedPath& out, const std::vector<NamedPath>& inputs) {
  for (const NamedPath& in : inputs)
    if (!in.path.empty() && SameFile(out.path, in.path))
      throw std::invalid_argument(out.flag + " " + out.path + " is the same file as " + in.flag +
                                  " " + in.path + ": refusing to overwrite an input");
}

void RequireWritableOutput(const std::string& path, const std::string& flag) {
  std::error_code ec;
  if (fs::is_directory(path, ec))
    throw io::IoError(flag + ": " + path + " is a directory, not an output file");
  RequireWritableIn(fs::path(path).parent_path(), flag, path);
}

void RequireWritableDirectory(const std::string& dir, const std::string& flag) {
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    throw io::IoError(flag + ": " + dir + " exists and is not a directory");
  RequireWritableIn(fs::path(dir), flag, dir);
}

const CLI::Validator& PositiveFinite() {
  static const CLI::Validator kPositiveFinite(
      [](std::string& text) {
        try {
          size_t used = 0;
          const double v = std::stod(text, &used);
          if (used == text.size() && std::isfinite(v) && v > 0.0) return std::string();
        } catch (const std::logic_error&) {
        }
        return "must be a finite number > 0, got \"" + text + "\"";
      },
      "> 0");
  return kPositiveFinite;
}

void AddTonemapCommand(CLI::App& app, const Globals&, int& exit_code) {
  struct Args {
    std::string in, out, scene, tone_mapping;
    double exposure = -1.0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "tonemap", "linear EXR -> display PNG with a scene card's (or the given) tone mapping");
  cmd->add_option("input", a->in, "linear EXR (channels R, G, B)")->required();
  cmd->add_option("output", a->out, "output PNG (.png: the only format written)")->required();
  cmd->add_option("--scene", a->scene, "take tone mapping and exposure from this scene card");
  cmd->add_option("--tone-mapping", a->tone_mapping,
                  "Linear|Reinhard|Cineon|ACESFilmic|AgX|Neutral (default ACESFilmic)");
  cmd->add_option("--exposure", a->exposure,
                  "exposure, a finite number > 0 (default: the --scene card's, else 1)")
      ->check(PositiveFinite());
  cmd->callback([a, &exit_code]() {
    try {
      std::string tm = "ACESFilmic";
      double exposure = 1.0;
      if (!a->scene.empty()) {
        const render::SceneCard card = render::LoadSceneCard(a->scene);
        tm = card.tone_mapping;
        exposure = card.exposure;
      }
      if (!a->tone_mapping.empty()) tm = a->tone_mapping;
      if (a->exposure > 0.0) exposure = a->exposure;  // given: checked > 0 and finite above
      // The output, before the image is read (session 27): a PNG by name, as it is by content
      // (before, "out.exr" received PNG bytes); not an input; a writable directory.
      std::string ext = std::filesystem::path(a->out).extension().string();
      for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
      if (ext != ".png")
        throw std::invalid_argument("output '" + a->out + "': must end in .png (tonemap writes "
                                    "an 8-bit sRGB PNG; the linear image is the EXR itself)");
      io::RequireOutputDirectory(a->out);
      RefuseOutputOverInput({"output", a->out}, {{"input", a->in}, {"--scene", a->scene}});
      RequireWritableOutput(a->out, "output");
      const io::Image img = io::ReadImage(a->in);
      int ch[3] = {-1, -1, -1};
      const char* names[3] = {"R", "G", "B"};
      for (int c = 0; c < img.channels(); ++c)
        for (int k = 0; k < 3; ++k)
          if (img.channel_names[size_t(c)] == names[k]) ch[k] = c;
      if (ch[0] < 0 || ch[1] < 0 || ch[2] < 0)
        throw io::IoError(a->in + ": needs channels R, G, B");
      std::vector<float> lin(size_t(img.width) * size_t(img.height) * 3);
      for (size_t p = 0; p < size_t(img.width) * size_t(img.height); ++p)
        for (size_t k = 0; k < 3; ++k) {
          const float v = img.pixels[p * size_t(img.channels()) + size_t(ch[k])];
          lin[p * 3 + k] = std::isfinite(v) ? v : 0.0f;
        }
      io::WritePng8(a->out, img.width, img.height,
                    ToDisplayImage(lin, render::ParseToneMapping(tm), exposure));
      exit_code = 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit tonemap: error: %s\n", 
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

void AddPreviewCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    std::string scene, material, model, out, ibl_engine = "filament", map_aniso_rule = "spec";
    std::string env_sun;  // "": the card's environment.sun (else auto, the commands' default)
    bool shadows = false;
    bool no_horizon_fade = false;
    bool no_card_visibility = false;
    std::string light_map_out;
    int exact_ibl = 0, exact_irradiance = 0;
    unsigned exact_ibl_seed = 1;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "render-preview", "render what the real-time engine draws for a scene and a material");
  // --help shows each default ("=filament"), as bench does (session 28: it showed none).
  cmd->option_defaults()->always_capture_default();
  cmd->add_option("--scene", args->scene, "scene card (JSON)")->required();
  cmd->add_option("--material", args->material, "material preset (JSON, docs/preset-format.md)")
      ->required();
  cmd->add_option("--model", args->model,
                  "expected model (cloth|standard|physical-sheen|gltf-sheen|woven|physical-aniso); an "
                  "error if the "
                  "preset is another model");
  cmd->add_option("--out", args->out, "output: .png (tone-mapped, sRGB) or .exr (linear)")
      ->required();
  cmd->add_flag("--shadows", args->shadows, "ray-traced light visibility (off by default; on "
                "when the scene card's \"visibility\" says \"shadows\": true)");
  cmd->add_flag("--no-card-visibility", args->no_card_visibility,
                "ignore the scene card's \"visibility\" block (its shadows and light map)");
  cmd->add_flag("--no-horizon-fade", args->no_horizon_fade,
                "measurement (woven): draw the environment's sun and panels as delta lights, "
                "without the fade across the surface's horizon (docs/sun.md \"Terminator "
                "fade\"; as before session 22)");
  cmd->add_option("--light-map-out", args->light_map_out,
                  "write the fabric's baked light map (the card's \"visibility\": "
                  "{\"light_map\"}) as an EXR: R, G, B = irradiance E (three.js lightMap, "
                  "intensity 1; no alpha channel, a texture takes A = 1); metadata: the uv box");
  
  cmd->add_option("--map-aniso-rule", args->map_aniso_rule,
                  "weave maps with weave_maps.anisotropy > 1: spec (EXT_texture_filter_anisotropic, "
                  "default; what the fit uses) or swiftshader (SwiftShader's rule, the WebGL2 of "
                  "the browser test; render/preview/weave_maps.h)")
      ->check(CLI::IsMember({"spec", "swiftshader"}));
  cmd->add_option("--ibl-engine", args->ibl_engine,
                  "whose image-based lighting: threejs (r187 PMREM), filament (SH + prefilter) or "
                  "auto (three.js for standard, physical-sheen, physical-aniso, woven and the seed "
                  "cloth); default filament")
      ->check(CLI::IsMember({"auto", "threejs", "filament"}));
  cmd->add_option("--exact-ibl", args->exact_ibl,
                  "measurement: integrate the environment exactly on the fabric (Monte Carlo, this "
                  "many directions per pixel, no split sum, no visibility); 0 = split sum (default)")
      ->check(CLI::Range(0, 65536));
  cmd->add_option("--exact-irradiance", args->exact_irradiance,
                  "measurement: the fabric's diffuse irradiance integrated exactly (Monte Carlo, "
                  "this many directions per pixel); the lobes keep the engine's IBL")
      ->check(CLI::Range(0, 65536));
  cmd->add_option("--env-sun", args->env_sun,
                  "the environment's sun as a directional light (docs/sun.md): auto (detect a "
                  "compact sun, split it off the IBL's map), off, or panels (auto, then up to 8 broad "
                  "bright sources such as softboxes, each one more light); default: the card's "
                  "environment.sun, else auto (web/ draws the same)");
  cmd->add_option("--exact-ibl-seed", args->exact_ibl_seed, "seed of --exact-ibl's directions (default 1)");
  cmd->callback([args, &g, &exit_code]() {
    try {
      io::RequireOutputDirectory(args->out);  // before the PMREM and the cache build
      if (!args->light_map_out.empty()) io::RequireOutputDirectory(args->light_map_out);
      // Case-insensitive, as tonemap and render-reference (session 28: "P.PNG" was refused).
      std::string ext = std::filesystem::path(args->out).extension().string();
      for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
      if (ext != ".png" && ext != ".exr") {
        std::fprintf(stderr, "clothfit render-preview: error: --out: '%s' must end in .png or .exr\n",
                     args->out.c_str());
        exit_code = 1;
        return;
      }
      // Not an input, and a directory that takes the file (session 27), before any work.
      RefuseOutputOverInput({"--out", args->out},
                            {{"--scene", args->scene}, {"--material", args->material}});
      RequireWritableOutput(args->out, "--out");
      if (!args->light_map_out.empty()) {
        RefuseOutputOverInput({"--light-map-out", args->light_map_out},
                              {{"--scene", args->scene}, {"--material", args->material},
                               {"--out", args->out}});
        RequireWritableOutput(args->light_map_out, "--light-map-out");
      }
      const render::MaterialPreset preset = render::ReadPreset(args->material);
      if (const auto fit = preset.extra.find("fit");
          !preset.yarn_lobe && fit != preset.extra.end() && fit->is_object() &&
          fit->contains("yarn_lobe"))
        std::fprintf(stderr,
                     "clothfit render-preview: warning: %s was fitted with the far-field yarn lobe "
                     "(fit.yarn_lobe, a measurement): drawn here with woven's own lobes, which "
                     "that fit did not use\n",
                     args->material.c_str());
      if (!args->model.empty() && render::ParseModelKind(args->model) != preset.model) {
        std::fprintf(stderr,
                     "clothfit render-preview: error: --model %s but %s is a %s preset\n",
                     args->model.c_str(), args->material.c_str(),
                     render::ToString(preset.model).c_str());
        exit_code = 1;
        return;
      }
      const render::Scene scene = render::LoadScene(args->scene);
      for (const std::string& w : scene.warnings)
        if (!g.quiet) std::fprintf(stderr, "clothfit: warning: %s\n", w.c_str());
      const auto env = LoadSceneEnvironment(scene, g.quiet);
      const auto no_light_map = [&] {
        return std::invalid_argument(
            "--light-map-out: " + limits::EscapeForMessage(args->scene) +
            " bakes no light map (the card needs \"visibility\": {\"light_map\": ...}, and "
            "not --no-card-visibility or --exact-ibl)");
      };
      if (!args->light_map_out.empty() &&  // checked before any work
          (!scene.card.visibility || !scene.card.visibility->light_map ||
           args->no_card_visibility || args->exact_ibl > 0))
        throw no_light_map();
      render::PreviewOptions o;
      o.model = preset.model;
      o.cloth = preset.cloth;
      o.woven = render::PreviewWovenOptions(preset);
      render::ApplyPresetYarnLobe(preset, &o);  // "woven": {"yarn_lobe"}
      // "weave_maps" (woven, physical-aniso): "uri" relative to the preset file first
      o.weave_maps = render::LoadPresetWeaveMaps(preset, args->material);
      if (o.weave_maps && args->map_aniso_rule == "swiftshader") {
        auto m = std::make_shared<render::WeaveMaps>(*o.weave_maps);
        m->aniso_rule = render::WeaveMaps::AnisoRule::kSwiftShader;
        o.weave_maps = m;
      }
      o.shadows = args->shadows;
      o.horizon_fade = !args->no_horizon_fade;
      // the card's light map bounces off the fabric with the material's own albedo (session 13)
      o.visibility.fabric_albedo = render::DiffuseAlbedo(preset);
      o.card_visibility = !args->no_card_visibility;
      if (preset.model == render::ModelKind::kPhysicalAniso)  // brdf/physical_aniso.h FromFlat
        o.anisotropy_rotation = preset.values.at(10);
      o.ibl_engine = args->ibl_engine == "threejs"    ? render::IblEngine::kThreejs
                     : args->ibl_engine == "filament" ? render::IblEngine::kFilament
                                                      : render::IblEngine::kAuto;
      if (preset.model == render::ModelKind::kWoven && preset.woven.ibl == woven::IblMode::kFis &&
          (!render::UsesWovenFis(o) || args->exact_ibl > 0) && !g.quiet)
        std::fprintf(stderr,
                     "clothfit: note: %s asks for woven \"ibl\": \"fis\"; FIS exists on the "
                     "three.js IBL engine only (--ibl-engine threejs or auto) and not with "
                     "--exact-ibl: rendering with the split sum\n",
                     limits::EscapeForMessage(args->material).c_str());
      if (!args->env_sun.empty()) o.env_sun = render::ParseSunMode(args->env_sun, "--env-sun");
      o.env_sun_default = render::kCliDefaultSunMode;  // s10-sun: auto (as web/ draws it)
      o.exact_ibl_samples = args->exact_ibl;
      o.exact_ibl_seed = args->exact_ibl_seed;
      o.exact_irradiance_samples = args->exact_irradiance;
      std::unique_ptr<render::PreviewCache> cache;
      std::vector<float> frame;
      if (o.exact_ibl_samples > 0 && env) {
        // Exact IBL caches N directions per fabric pixel: build and evaluate the frame in chunks
        // of rows (PreviewOptions::sample_mask) so the cache stays a few hundred MB.
        const int W = scene.card.width, H = scene.card.height;
        const int rows = std::max(1, (1 << 22) / std::max(1, W * o.exact_ibl_samples));
        size_t fabric_pixels = 0;
        for (int y0 = 0; y0 < H; y0 += rows) {
          o.sample_mask.assign(size_t(W) * size_t(H), 0);
          for (int y = y0; y < std::min(H, y0 + rows); ++y)
            std::fill(o.sample_mask.begin() + long(y) * W, o.sample_mask.begin() + long(y + 1) * W, 1);
          cache = render::PreviewCache::Build(scene, env.get(), o);
          std::vector<Rgb<double>> fabric;
          render::EvaluatePreview(*cache, preset.values.data(), fabric);
          std::vector<float> part = render::ComposeFrame(*cache, fabric);
          if (frame.empty()) frame = part;
          for (size_t i = 0; i < cache->pixels.size(); ++i)
            for (size_t k = 0; k < 3; ++k)
              frame[size_t(cache->pixels[i]) * 3 + k] = part[size_t(cache->pixels[i]) * 3 + k];
          fabric_pixels += cache->pixels.size();
        }
        std::printf("render-preview: exact IBL, %d directions per pixel, %zu fabric pixels in "
                    "all chunks (the line below counts the last chunk)\n",
                    o.exact_ibl_samples, fabric_pixels);
      } else {
        cache = render::PreviewCache::Build(scene, env.get(), o);
        std::vector<Rgb<double>> fabric;
        render::EvaluatePreview(*cache, preset.values.data(), fabric);
        frame = render::ComposeFrame(*cache, fabric);
      }
      if (!args->light_map_out.empty()) {  // the fabric's baked light map (session 13)
        const render::UvVisibilityMap* lm = nullptr;
        for (const auto& m : cache->uv_visibility)
          if (m.size > 0 && !lm) lm = &m;
        if (!lm || !cache->options.visibility.indirect) throw no_light_map();
        io::Image img;
        img.width = lm->size;
        img.height = lm->size;
        img.channel_names = {"R", "G", "B"};
        img.pixels.resize(size_t(lm->size) * size_t(lm->size) * 3);
        for (size_t i = 0; i < img.pixels.size(); ++i)
          img.pixels[i] = float(kPi * double(lm->indirect[i]));  // E = pi x (E_ind / pi)
        img.metadata["clothfit:content"] =
            "light map: indirect irradiance E (linear Rec.709, W/m^2 in the lights' units) of "
            "the fabric mesh, three.js material.lightMap at lightMapIntensity 1";
        img.metadata["clothfit:mesh"] = scene.meshes[size_t(lm->mesh)].name;
        char box[160];
        std::snprintf(box, sizeof box, "%.9g %.9g %.9g %.9g", lm->uv_min[0], lm->uv_min[1],
                      lm->uv_max[0], lm->uv_max[1]);
        img.metadata["clothfit:uv_box"] = box;  // u0 v0 u1 v1
        img.metadata["clothfit:uv_convention"] =
            "texel (i, j) at uv = uv0 + (i + 0.5, j + 0.5) / size x (uv1 - uv0); row j = 0 is the "
            "first row of the file (glTF v, flipY false); bilinear, clamp to edge; offset = "
            "-uv0 / (uv1 - uv0), repeat = 1 / (uv1 - uv0) on uv channel 0";
        img.metadata["clothfit:side"] = "the side the mesh's vertex normals face";
        io::WriteExr(args->light_map_out, img);
        if (!g.quiet)
          std::printf("render-preview: light map %dx%d -> %s\n", lm->size, lm->size,
                      args->light_map_out.c_str());
      }
      if (ext == ".exr") {
        io::Image img;
        img.width = cache->width;
        img.height = cache->height;
        img.channel_names = {"R", "G", "B", "fabric"};
        img.pixels.resize(size_t(img.width) * size_t(img.height) * 4);
        for (size_t p = 0; p < size_t(img.width) * size_t(img.height); ++p) {
          for (size_t k = 0; k < 3; ++k) img.pixels[p * 4 + k] = frame[p * 3 + k];
          img.pixels[p * 4 + 3] = cache->fabric_mask[p];
        }
        img.metadata["clothfit:colour_space"] = "linear Rec.709 / sRGB primaries (before tone mapping)";
        img.metadata["clothfit:model"] = render::ToString(preset.model);
        img.metadata["clothfit:engine"] = render::EngineOf(preset.model);
        io::WriteExr(args->out, img);
      } else {
        const auto op = render::ParseToneMapping(scene.card.tone_mapping);
        io::WritePng8(args->out, cache->width, cache->height,
                      ToDisplayImage(frame, op, scene.card.exposure));
      }
      if (!cache->sun_summary.empty() && cache->sun_summary != "no sun: off")
        std::printf("render-preview: environment %s\n", cache->sun_summary.c_str());
      std::printf("render-preview: %s (%s) on %s: %dx%d, %zu fabric pixels, cache %.3f s -> %s\n",
                  args->material.c_str(), render::ToString(preset.model).c_str(),
                  args->scene.c_str(), cache->width, cache->height, cache->pixels.size(),
                  cache->build_seconds, args->out.c_str());
      exit_code = 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit render-preview: error: %s\n", 
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
