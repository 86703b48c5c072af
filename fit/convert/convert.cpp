#include "fit/convert/convert.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>
#include <sstream>

#include "fit/brdf_fit.h"
#include "fit/convert/convert_io.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"

namespace clothfit::fit {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using render::ModelKind;

const std::vector<std::string> kTargets = {"preset", "threejs", "gltf", "filament", "preset-maps"};
const std::set<std::string> kInputExt = {".json", ".gltf", ".glb", ".binary", ".merl"};

struct Fnv {
  uint64_t h = 1469598103934665603ull;
  void Add(const void* p, size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  }
  void Add(const std::string& s) {
    Add(s.data(), s.size());
    Add("\0", 1);
  }
  // Hashes a regular file's bytes, up to the size fstat reports on the open descriptor (a
  // /proc file or a device would otherwise be read without end).
  void AddFile(const std::string& path) {
    size_t size = 0;
    try {
      size = limits::CheckedFileSize(path, limits::kMaxImageFileBytes, "file (for the content hash)");
    } catch (const limits::InputError& e) {
      throw ConvertError(e.what());
    }
    std::ifstream in(path, std::ios::binary);
    if (!in)
      throw ConvertError(limits::EscapeForMessage(path, 400) +
                         ": file: cannot open (for the content hash)");
    char buf[1 << 16];
    size_t left = size;
    while (in && left > 0) {
      in.read(buf, std::streamsize(std::min(left, sizeof buf)));
      const size_t got = size_t(in.gcount());
      Add(buf, got);
      left -= std::min(left, got);
    }
    Add(std::string("|eof"));
  }
};

std::string HexString(uint64_t h) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

std::string Uuid(uint64_t a) {
  Fnv f;
  f.h = a;
  f.Add(std::string("uuid"));
  const std::string s = HexString(a) + HexString(f.h);
  return s.substr(0, 8) + "-" + s.substr(8, 4) + "-4" + s.substr(13, 3) + "-8" + s.substr(17, 3) +
         "-" + s.substr(20, 12);
}

std::string Sanitise(const std::string& s) {
  std::string out;
  for (char c : s)
    out += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.') ? c : '_';
  return out;
}

std::string StemOf(const fs::path& rel) {
  fs::path p = rel;
  p.replace_extension();
  std::string s = p.generic_string();
  for (char& c : s)
    if (c == '/') c = '_';
  return Sanitise(s);
}

bool Wants(const ConvertOptions& o, const std::string& t) {
  return std::find(o.targets.begin(), o.targets.end(), t) != o.targets.end();
}

std::string OptionsKey(const ConvertOptions& o) {
  std::vector<std::string> t = o.targets;
  std::sort(t.begin(), t.end());
  std::string k;
  for (const auto& s : t) k += s + ",";
  k += std::string(cloth::ToString(o.cloth.variant)) + "/" +
       std::string(cloth::ToString(o.cloth.sheen_default)) + "/" +
       (o.cloth.subsurface ? "sub" : "nosub") + "/" +
       (o.cloth.platform == Platform::kMobile ? "mobile" : "desktop");
  return k;
}

// What is written for one source: the requested targets minus those it is refused for by
// design (woven: no engine form; physical-aniso maps with a relief normal map: not baked),
// each refusal with its reason. The other targets are written; the refusals are reported per
// material and target (ItemResult::refused), not as a failure (docs/convert.md section 4).
struct Plan {
  bool preset = false, threejs = false, gltf = false, filament = false, preset_maps = false;
  bool bake_weave = false;  // physical-aniso weave maps baked into PNG textures
  std::vector<std::pair<std::string, std::string>> refused;
  bool Empty() const { return !preset && !threejs && !gltf && !filament && !preset_maps; }
};

Plan PlanFor(const ConvertOptions& o, const SourceMaterial& m) {
  Plan p;
  p.preset = Wants(o, "preset");
  p.threejs = Wants(o, "threejs");
  p.gltf = Wants(o, "gltf");
  p.filament = Wants(o, "filament");
  p.preset_maps = Wants(o, "preset-maps") && m.analytic;  // other sources: a note, no file
  auto refuse_engines = [&](const std::string& why) {
    for (const char* t : {"threejs", "gltf"})
      if (Wants(o, t)) p.refused.emplace_back(t, why);
    p.threejs = p.gltf = false;
  };
  // woven: no engine form (docs/convert.md, "Weave maps in glTF and three.js"): refused for
  // the engine targets rather than silently fitted without its maps and lobes.
  if (m.analytic && m.analytic->model == ModelKind::kWoven && (p.threejs || p.gltf))
    refuse_engines(
        m.file + ": model: 'woven' (brdf/woven.h) has no exact glTF or three.js form: its two "
        "yarn lobes (warp- and weft-aligned anisotropic GGX under the phase Fresnel f0 + (1 - f0) "
        "exp(-2 beta LoH^2), weighted per texel by the weave maps' warp/weft channels) cannot be "
        "written as KHR_materials_anisotropy/specular/sheen or MeshPhysicalMaterial (one "
        "anisotropic lobe, Schlick Fresnel); " +
        std::string(p.preset_maps ? "its preset-maps output carries it exactly"
                                  : "--to preset-maps carries it exactly") +
        " (web/clothfit.js draws woven presets); `clothfit fit --model physical-aniso` gives the "
        "nearest three.js material");
  const bool aniso_maps =
      m.analytic && m.analytic->model == ModelKind::kPhysicalAniso && m.weave_maps;
  if (aniso_maps && (p.threejs || p.gltf) && m.weave_maps->has_normals())
    refuse_engines(m.file + ": weave_maps: the maps carry a relief normal map (N.X, N.Y, N.Z), "
                   "which this exporter does not bake into a normalTexture");
  // A physical-aniso preset with weave maps, for the three.js or glTF target: the maps are
  // baked into PNG textures (fit/convert/weave_textures.h) that both outputs reference.
  p.bake_weave = aniso_maps && (p.threejs || p.gltf);
  return p;
}

std::vector<std::string> OutputsFor(const ConvertOptions& o, const std::string& stem,
                                    const SourceMaterial& m) {
  const Plan p = PlanFor(o, m);
  std::vector<std::string> out;
  const fs::path d(o.out_dir);
  if (p.preset) out.push_back((d / (stem + ".preset.json")).string());
  if (p.threejs) {
    out.push_back((d / (stem + ".three.json")).string());
    out.push_back((d / (stem + ".meshcloth.json")).string());
  }
  if (p.gltf) out.push_back((d / (stem + ".gltf")).string());
  if (p.filament) out.push_back((d / (stem + ".mat")).string());
  if (p.bake_weave) {
    out.push_back((d / (stem + ".basecolor.png")).string());
    out.push_back((d / (stem + ".anisotropy.png")).string());
  }
  if (p.preset_maps) {  // the source preset itself, with its maps
    out.push_back((d / (stem + ".maps.preset.json")).string());
    if (!m.weave_maps_file.empty()) out.push_back((d / (stem + ".maps.weave.exr")).string());
    if (!m.glint_file.empty()) out.push_back((d / (stem + ".maps.glint.exr")).string());
  }
  return out;
}

std::string RecordPath(const ConvertOptions& o, const std::string& stem) {
  return (fs::path(o.out_dir) / ".clothfit-convert" / (stem + ".json")).string();
}

bool UpToDate(const ConvertOptions& o, const std::string& stem, const SourceMaterial& m,
              const std::string& hash, double* error) {
  json r;
  try {
    const std::string text =
        limits::ReadFileBounded(RecordPath(o, stem), limits::kMaxJsonFileBytes, "resume record");
    if (limits::FindJsonDepthExcess(text)) return false;
    r = json::parse(text);
  } catch (const std::exception&) {
    return false;  // an unreadable record means: convert again
  }
  if (r.value("hash", "") != hash) return false;
  for (const std::string& f : OutputsFor(o, stem, m))
    if (!fs::exists(f)) return false;
  *error = r.value("error", -1.0);
  return true;
}

BrdfFitResult FitOrThrow(const BrdfSamples& s, ModelKind model, const cloth::Options& co,
                         const SourceMaterial& m) {
  BrdfFitOptions fo;
  fo.model = model;
  fo.cloth = co;
  // Fabrics are dielectric: metalness is held at 0 (as the image-fit baselines do), except
  // that a source of the target model starts from, and keeps, its own value.
  if (model == ModelKind::kPhysicalSheen || model == ModelKind::kStandard)
    fo.locked = {"metalness"};
  if (model == ModelKind::kGltfSheen) fo.locked = {"metallic"};
  // The engines' models cost several times the cloth model per Jacobian (tables, Lambda
  // curves); their fits stop after 15 iterations (docs/convert.md: error effect measured).
  if (model != ModelKind::kCloth) fo.max_iterations = 15;
  if (m.analytic && m.analytic->model == model) fo.source_preset = &*m.analytic;
  BrdfFitResult r = FitBrdf(s, fo);
  if (!r.usable)
    throw ConvertError(m.file + ": " + m.name + ": " + render::ToString(model) +
                       " fit failed: " + r.message);
  return r;
}

void ConvertOne(const SourceMaterial& m, const ConvertOptions& o, const Plan& plan,
                const std::string& stem, const std::string& hash, ItemResult& item) {
  const BrdfSamples s = SampleSource(m);
  Converted c;
  c.name = m.name;
  c.maps = m.maps;
  c.double_sided = m.double_sided;
  const BrdfFitResult cr = FitOrThrow(s, ModelKind::kCloth, o.cloth, m);
  c.cloth = cr.preset;
  item.error = cr.error;
  json fits = {{"cloth", cr.error}};
  json iterations = {{"cloth", cr.iterations}};
  // A physical-aniso source is MeshPhysicalMaterial itself: the three.js and glTF targets
  // carry it exactly instead of fitting physical-sheen / gltf-sheen to it.
  if (m.analytic && m.analytic->model == ModelKind::kPhysicalAniso) {
    c.physical_aniso = *m.analytic;
    fits["physical-aniso"] = 0.0;
  }
  if (plan.threejs) {
    if (!c.physical_aniso) {
      const BrdfFitResult r = FitOrThrow(s, ModelKind::kPhysicalSheen, {}, m);
      c.physical_sheen = r.preset;
      fits["physical-sheen"] = r.error;
      iterations["physical-sheen"] = r.iterations;
    }
    if (o.cloth.variant != cloth::Variant::kSeedThreejs) {
      cloth::Options seed;
      seed.variant = cloth::Variant::kSeedThreejs;  // the seed's MeshClothMaterial, its own fit
      const BrdfFitResult sr = FitOrThrow(s, ModelKind::kCloth, seed, m);
      c.seed_cloth = sr.preset;
      fits["cloth/seed-threejs"] = sr.error;
      iterations["cloth/seed-threejs"] = sr.iterations;
    }
  }
  if (plan.gltf && !c.physical_aniso) {
    const BrdfFitResult r = FitOrThrow(s, ModelKind::kGltfSheen, {}, m);
    c.gltf_sheen = r.preset;
    fits["gltf-sheen"] = r.error;
    iterations["gltf-sheen"] = r.iterations;
  }
  c.provenance = {{"tool", kToolVersion},
                  {"source", m.file},
                  {"material", m.name},
                  {"kind", m.kind},
                  {"content_hash", hash},
                  {"uuid", Uuid(std::stoull(hash, nullptr, 16))},
                  {"fit",
                   {{"space",
                     "square root of cosine-weighted BRDF (Hellinger), half-vector canonical "
                     "directions (docs/convert.md)"},
                    {"directions", CanonicalDirections().size()},
                    {"error", fits},
                    {"starts", cr.starts},
                    {"iterations", iterations}}},
                  {"notes", m.notes}};
  const std::vector<std::string> outs = OutputsFor(o, stem, m);
  if (plan.bake_weave) {
    c.weave = BakePhysicalAnisoTextures(*m.analytic, *m.weave_maps);
    const WeaveTextures& w = *c.weave;
    c.base_color_png = (fs::path(o.out_dir) / (stem + ".basecolor.png")).string();
    c.anisotropy_png = (fs::path(o.out_dir) / (stem + ".anisotropy.png")).string();
    WritePngFile(c.base_color_png, w.size, w.size, 3, w.base_color, true);
    WritePngFile(c.anisotropy_png, w.size, w.size, 3, w.anisotropy, false);
    char line[256];
    std::snprintf(line, sizeof line,
                  "weave maps baked to textures: base colour max error %.2e linear (%.2e "
                  "relative), %d clipped; anisotropy strength %.2e, direction %.1e rad",
                  w.base_max_abs_error, w.base_max_rel_error, w.clipped_texels,
                  w.strength_max_abs_error, w.direction_max_angle_error);
    item.notes.push_back(line);
  } else if (m.weave_maps && (plan.preset || plan.filament)) {
    item.notes.push_back("weave maps not carried by the preset/filament targets (cloth fits)");
  }
  if (Wants(o, "preset-maps") && !m.analytic)
    item.notes.push_back("preset-maps: not a clothfit preset source, nothing written");
  size_t k = 0;
  if (plan.preset) WriteClothPreset(outs[k++], c);
  if (plan.threejs) {
    WriteThreejsPhysical(outs[k++], c);
    WriteThreejsCloth(outs[k++], c);
  }
  if (plan.gltf) WriteGltf(outs[k++], c);
  if (plan.filament) WriteFilamentMat(outs[k++], c);
  if (plan.preset_maps)
    WritePresetWithMaps((fs::path(o.out_dir) / (stem + ".maps.preset.json")).string(), m,
                        c.provenance);
  item.outputs = outs;
  const json record = {{"hash", hash},
                       {"source", m.file},
                       {"material", m.name},
                       {"error", cr.error},
                       {"outputs", outs}};
  io::WriteTextAtomic(RecordPath(o, stem), limits::DumpJson(record) + "\n");
}

void ConvertFile(const InputFile& in, const ConvertOptions& o, std::vector<ItemResult>& out,
                 const std::function<void(int)>& done) {
  std::vector<SourceMaterial> mats;
  try {
    mats = ReadMaterials(in.path, limits::PathPolicy{in.root, o.allow_outside_paths});
  } catch (const NotAMaterial& e) {  // clothfit's own non-material documents: a note
    ItemResult r;
    r.file = in.path;
    r.stem = in.stem;
    r.status = "ignored";
    r.notes.push_back(limits::EscapeForMessage(e.what(), 2000));
    out.push_back(r);
    done(1);
    return;
  } catch (const std::bad_alloc&) {
    ItemResult r;
    r.file = in.path;
    r.stem = in.stem;
    r.status = "failed";
    r.reason = limits::EscapeForMessage(in.path, 400) +
               ": out of memory reading this input (limits: docs/reliability.md)";
    out.push_back(r);
    done(1);
    return;
  } catch (const std::exception& e) {
    ItemResult r;
    r.file = in.path;
    r.stem = in.stem;
    r.status = "failed";
    r.reason = limits::EscapeForMessage(e.what(), 2000);
    out.push_back(r);
    done(1);
    return;
  }
  for (const SourceMaterial& m : mats) {
    const auto t0 = std::chrono::steady_clock::now();
    ItemResult r;
    r.file = in.path;
    r.material = m.name;
    r.kind = m.kind;
    r.notes = m.notes;
    r.stem = mats.size() == 1 ? in.stem : in.stem + "__" + Sanitise(m.name);
    try {
      Fnv h;
      h.Add(std::string(kToolVersion));
      h.Add(std::string(kFitRevision));  // outputs of an older fit are converted again
      h.Add(OptionsKey(o));
      h.Add(m.name);
      h.AddFile(in.path);
      for (const std::string& d : m.dependencies) h.AddFile(d);
      const std::string hash = HexString(h.h);
      const Plan plan = PlanFor(o, m);
      for (const auto& [target, why] : plan.refused)
        r.refused.emplace_back(target, limits::EscapeForMessage(why, 2000));
      double err = -1.0;
      if (plan.Empty() && !plan.refused.empty()) {
        r.status = "refused";  // nothing requested can be written: no fit, no record
      } else if (UpToDate(o, r.stem, m, hash, &err)) {
        r.status = "skipped";
        r.error = err;
        r.outputs = OutputsFor(o, r.stem, m);
      } else {
        ConvertOne(m, o, plan, r.stem, hash, r);
        r.status = "converted";
      }
    } catch (const std::exception& e) {
      r.status = "failed";
      r.reason = limits::EscapeForMessage(e.what(), 2000);
    }
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out.push_back(r);
  }
  done(int(mats.size()));
}

}  // namespace

void CheckTargets(const std::vector<std::string>& targets) {
  if (targets.empty()) throw std::invalid_argument("--to: no target given");
  for (const std::string& t : targets)
    if (std::find(kTargets.begin(), kTargets.end(), t) == kTargets.end())
      throw std::invalid_argument("--to: unknown target '" + t +
                                  "' (valid: preset, threejs, gltf, filament, preset-maps)");
}

std::vector<InputFile> ExpandInputs(const std::vector<std::string>& args,
                                    const std::string& exclude) {
  std::vector<InputFile> out;
  std::error_code ex_ec;
  const fs::path skip = exclude.empty() ? fs::path() : fs::weakly_canonical(exclude, ex_ec);
  auto add_dir = [&](const fs::path& dir) {
    std::vector<fs::path> files;
    for (auto it = fs::recursive_directory_iterator(dir); it != fs::recursive_directory_iterator();
         ++it) {
      const auto& e = *it;
      std::error_code ec;
      if (!skip.empty() && e.is_directory() && fs::weakly_canonical(e.path(), ec) == skip) {
        it.disable_recursion_pending();
        continue;
      }
      if (!e.is_regular_file()) continue;
      const std::string name = e.path().filename().string();
      if (name.empty() || name[0] == '.') continue;
      std::string ext = e.path().extension().string();
      for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
      if (kInputExt.count(ext)) files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files)
      out.push_back({f.string(), StemOf(fs::relative(f, dir)), dir.string()});
  };
  for (const std::string& a : args) {
    std::error_code ec;
    const fs::path p(a);
    if (fs::is_directory(p, ec)) {
      add_dir(p);
    } else if (fs::is_regular_file(p, ec) && p.extension() == ".txt") {
      std::ifstream in(p);
      std::string line;
      int n = 0;
      while (std::getline(in, line)) {
        ++n;
        const size_t b = line.find_first_not_of(" \t\r");
        if (b == std::string::npos || line[b] == '#') continue;
        const size_t e = line.find_last_not_of(" \t\r");
        const std::string entry = line.substr(b, e - b + 1);
        const fs::path f =
            fs::path(entry).is_absolute() ? fs::path(entry) : p.parent_path() / entry;
        if (fs::is_directory(f, ec)) {
          add_dir(f);
        } else if (fs::is_regular_file(f, ec)) {
          out.push_back(
              {f.string(), StemOf(fs::path(entry).is_absolute() ? f.filename() : fs::path(entry)),
               f.parent_path().string()});
        } else {
          throw ConvertError(a + ":" + std::to_string(n) + ": no such file or directory '" + entry +
                             "'");
        }
      }
    } else if (fs::is_regular_file(p, ec)) {
      out.push_back({p.string(), StemOf(p.filename()), p.parent_path().string()});
    } else {
      throw ConvertError(a + ": no such file or directory");
    }
  }
  std::sort(out.begin(), out.end(), [](const InputFile& x, const InputFile& y) {
    return x.stem != y.stem ? x.stem < y.stem : x.path < y.path;
  });
  out.erase(std::unique(out.begin(), out.end(),
                        [](const InputFile& x, const InputFile& y) { return x.path == y.path; }),
            out.end());
  return out;
}

ConvertReport RunConvert(const std::vector<InputFile>& all, const ConvertOptions& o) {
  CheckTargets(o.targets);
  if (o.shard_count < 1 || o.shard_index < 0 || o.shard_index >= o.shard_count)
    throw std::invalid_argument("--shard: index must be in [0, N)");
  const auto t0 = std::chrono::steady_clock::now();
  fs::create_directories(fs::path(o.out_dir) / ".clothfit-convert");
  std::vector<InputFile> mine;
  for (size_t i = 0; i < all.size(); ++i)
    if (int(i % size_t(o.shard_count)) == o.shard_index) mine.push_back(all[i]);
  // Output stems must be unique (two inputs a/x.json and a_x.json would collide).
  std::vector<std::string> collide(mine.size());
  {
    std::map<std::string, std::string> first;
    for (size_t i = 0; i < mine.size(); ++i) {
      auto [it, fresh] = first.emplace(mine[i].stem, mine[i].path);
      if (!fresh) collide[i] = "output name '" + mine[i].stem + "' collides with " + it->second;
    }
  }
  std::vector<std::vector<ItemResult>> per_file(mine.size());
  std::mutex mu;
  long long done = 0, known = (long long)mine.size();
  auto tick = [&](int n) {
    std::lock_guard<std::mutex> lock(mu);
    done += n;
    known += n - 1;  // a file counts as one until its materials are known
    if (o.progress) o.progress(done, known);
  };
  std::unique_ptr<tbb::global_control> gc;
  if (o.jobs > 0)
    gc = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               size_t(o.jobs));
  tbb::parallel_for(size_t(0), mine.size(), [&](size_t i) {
    if (!collide[i].empty()) {
      ItemResult r;
      r.file = mine[i].path;
      r.stem = mine[i].stem;
      r.status = "failed";
      r.reason = mine[i].path + ": " + collide[i];
      per_file[i].push_back(r);
      tick(1);
      return;
    }
    ConvertFile(mine[i], o, per_file[i], tick);
  });
  ConvertReport rep;
  rep.files = int(mine.size());
  for (auto& v : per_file)
    for (auto& r : v) {
      rep.converted += r.status == "converted";
      rep.skipped += r.status == "skipped";
      rep.failed += r.status == "failed";
      rep.refused += r.status == "refused";
      rep.ignored += r.status == "ignored";
      rep.refused_targets += int(r.refused.size());
      rep.items.push_back(std::move(r));
    }
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return rep;
}

std::string SummaryTable(const ConvertReport& r) {
  std::ostringstream s;
  std::vector<double> errors;
  for (const ItemResult& i : r.items)
    if (i.error >= 0) errors.push_back(i.error);
  std::sort(errors.begin(), errors.end());
  char buf[256];
  s << "| status | materials |\n|---|---:|\n";
  s << "| converted | " << r.converted << " |\n| skipped (up to date) | " << r.skipped
    << " |\n| failed | " << r.failed << " |\n";
  // By design, not failures (exit status 0): targets a source has no form in, and clothfit
  // documents that are not materials.
  if (r.refused)
    s << "| refused (no requested target can hold the source) | " << r.refused << " |\n";
  if (r.refused_targets)
    s << "| refused targets (by design; listed below) | " << r.refused_targets
      << " |\n";
  if (r.ignored) s << "| ignored (not a material) | " << r.ignored << " |\n";
  std::snprintf(buf, sizeof buf, "%d input files, %.2f s, %.1f materials/s converted\n", r.files,
                r.seconds, r.seconds > 0 ? r.converted / r.seconds : 0.0);
  s << buf;
  if (!errors.empty()) {
    std::snprintf(buf, sizeof buf,
                  "cloth fit error (square-root units): median %.4f, 90th %.4f, max %.4f over %zu\n",
                  errors[errors.size() / 2], errors[errors.size() * 9 / 10], errors.back(),
                  errors.size());
    s << buf;
  }
  if (r.refused_targets) {
    s << "\n| input | material | refused targets | reason |\n|---|---|---|---|\n";
    for (const ItemResult& i : r.items)
      for (size_t k = 0; k < i.refused.size(); ++k) {
        bool seen = false;  // one row per reason, naming every target it refuses
        for (size_t e = 0; e < k; ++e) seen = seen || i.refused[e].second == i.refused[k].second;
        if (seen) continue;
        std::string targets;
        for (const auto& [t, why] : i.refused)
          if (why == i.refused[k].second) targets += (targets.empty() ? "" : ", ") + t;
        s << "| " << limits::EscapeForMessage(i.file, 400) << " | "
          << (i.material.empty() ? "-" : limits::EscapeForMessage(i.material, 200)) << " | "
          << targets << " | " << i.refused[k].second << " |\n";
      }
  }
  if (r.ignored) {
    s << "\n| ignored input | note |\n|---|---|\n";
    for (const ItemResult& i : r.items)
      if (i.status == "ignored")
        s << "| " << limits::EscapeForMessage(i.file, 400) << " | "
          << (i.notes.empty() ? "" : i.notes.front()) << " |\n";
  }
  if (r.failed) {
    s << "\n| failed input | material | reason |\n|---|---|---|\n";
    for (const ItemResult& i : r.items)
      if (i.status == "failed")
        s << "| " << limits::EscapeForMessage(i.file, 400) << " | "
          << (i.material.empty() ? "-" : limits::EscapeForMessage(i.material, 200)) << " | "
          << i.reason
          << " |\n";
  }
  return s.str();
}

nlohmann::json ReportJson(const ConvertReport& r, const ConvertOptions& o) {
  json items = json::array();
  for (const ItemResult& i : r.items) {
    json j = {{"file", i.file},       {"material", i.material}, {"stem", i.stem},
              {"kind", i.kind},       {"status", i.status},     {"seconds", i.seconds},
              {"outputs", i.outputs}, {"notes", i.notes}};
    if (i.error >= 0) j["error"] = i.error;
    if (!i.reason.empty()) j["reason"] = i.reason;
    if (!i.refused.empty()) {
      j["refused"] = json::object();  // target -> reason
      for (const auto& [target, why] : i.refused) j["refused"][target] = why;
    }
    items.push_back(j);
  }
  return {{"tool", kToolVersion},
          {"targets", o.targets},
          {"shard", {{"index", o.shard_index}, {"count", o.shard_count}}},
          {"files", r.files},
          {"converted", r.converted},
          {"skipped", r.skipped},
          {"failed", r.failed},
          {"refused", r.refused},
          {"refused_targets", r.refused_targets},
          {"ignored", r.ignored},
          {"seconds", r.seconds},
          {"items", items}};
}

std::string LogName(const ConvertOptions& o) {
  if (o.shard_count == 1) return "convert-log.json";
  return "convert-log.shard-" + std::to_string(o.shard_index) + "-of-" +
         std::to_string(o.shard_count) + ".json";
}

}  // namespace clothfit::fit
