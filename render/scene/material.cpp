#include "render/scene/material.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "brdf/gltf_sheen.h"
#include "brdf/physical_aniso.h"
#include "brdf/physical_sheen.h"
#include "brdf/standard.h"
#include "brdf/woven.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"

namespace clothfit::render {

using nlohmann::json;

std::string ToString(ModelKind m) {
  switch (m) {
    case ModelKind::kCloth: return "cloth";
    case ModelKind::kStandard: return "standard";
    case ModelKind::kPhysicalSheen: return "physical-sheen";
    case ModelKind::kGltfSheen: return "gltf-sheen";
    case ModelKind::kWoven: return "woven";
    case ModelKind::kPhysicalAniso: return "physical-aniso";
  }
  return "?";
}

ModelKind ParseModelKind(const std::string& s) {
  if (s == "cloth") return ModelKind::kCloth;
  if (s == "standard") return ModelKind::kStandard;
  if (s == "physical-sheen") return ModelKind::kPhysicalSheen;
  if (s == "gltf-sheen") return ModelKind::kGltfSheen;
  if (s == "woven") return ModelKind::kWoven;
  if (s == "physical-aniso") return ModelKind::kPhysicalAniso;
  throw std::invalid_argument("unknown model '" + limits::EscapeForMessage(s, 80) +
                              "' (valid: cloth, standard, physical-sheen, gltf-sheen, woven, physical-aniso)");
}

std::span<const ParamInfo> ParameterTable(ModelKind m) {
  switch (m) {
    case ModelKind::kCloth: return cloth::kParameterTable;
    case ModelKind::kStandard: return standard::kParameterTable;
    case ModelKind::kPhysicalSheen: return physical_sheen::kParameterTable;
    case ModelKind::kGltfSheen: return gltf_sheen::kParameterTable;
    case ModelKind::kWoven: return woven::kParameterTable;
    case ModelKind::kPhysicalAniso: return physical_aniso::kParameterTable;
  }
  return {};
}

std::string EngineOf(ModelKind m) {
  switch (m) {
    case ModelKind::kCloth: return "Filament cloth shading model / seed MeshClothMaterial (three.js fork)";
    case ModelKind::kStandard: return std::string(standard::kEngine);
    case ModelKind::kPhysicalSheen: return std::string(physical_sheen::kEngine);
    case ModelKind::kGltfSheen: return std::string(gltf_sheen::kEngine);
    case ModelKind::kWoven: return std::string(woven::kEngine);
    case ModelKind::kPhysicalAniso: return std::string(physical_aniso::kEngine);
  }
  return "?";
}

std::pair<double, double> PresetRange(const ParamInfo& p) {
  // Colours and metalness must be in range; roughness values may be given below the engine
  // clamp (the engine clamps them), but not below 0.
  const bool is_roughness = p.name.find("roughness") != std::string_view::npos;
  return {is_roughness ? 0.0 : p.lower, p.upper};
}

int MaterialPreset::Offset(const std::string& name) const {
  int off = 0;
  for (const ParamInfo& p : ParameterTable(model)) {
    if (p.name == name) return off;
    off += p.size;
  }
  throw std::invalid_argument("model " + ToString(model) + " has no parameter '" + name + "'");
}

woven::Options PreviewWovenOptions(const MaterialPreset& p) {
  woven::Options o = p.woven;
  if (p.model == ModelKind::kWoven) {
    o.bent_anisotropy = p.values.at(size_t(p.Offset("anisotropy")));
    o.bent_twist = p.values.at(size_t(p.Offset("twist")));
  }
  return o;
}

MaterialPreset DefaultPreset(ModelKind m) {
  MaterialPreset p;
  p.model = m;
  for (const ParamInfo& info : ParameterTable(m))
    for (int c = 0; c < info.size; ++c) p.values.push_back(info.def[size_t(c)]);
  return p;
}

namespace {

[[noreturn]] void Fail(const std::string& where, const std::string& field, const std::string& msg) {
  // Field names can hold untrusted keys ("parameters.<key>"): escaped, never raw.
  throw MaterialError(where + ": " + limits::EscapeForMessage(field, 200) + ": " + msg);
}

// An unknown top-level ASCII key that is a case variant of `known`, one edit from it when
// `known` has 6 or 7 letters, or two when it has 8 or more (a swap of two adjacent letters is
// one edit), is taken for a typo and refused, naming the key it resembles.
void CheckNotNearMiss(const std::string& key, const std::string& known, const std::string& where) {
  // ASCII keys only (a key with other bytes is never taken for a typo: web/clothfit.js counts
  // UTF-16 units, this reader bytes, and the two must agree). Short names only by case: a
  // one-letter change of a 4- or 5-letter name ("mode", "size", "names") is as likely a new
  // field as a typo.
  if (!std::all_of(key.begin(), key.end(), [](char c) { return (unsigned char)c < 0x80; })) return;
  const size_t d = limits::NameDistance(key, known, /*fold_case=*/true);
  const size_t limit = known.size() >= 8 ? 2 : known.size() >= 6 ? 1 : 0;
  if (d <= limit)
    Fail(where, key, "unknown field; did you mean '" + known + "'? (a misspelt field would be "
                     "ignored and the material drawn without it)");
}

double Number(const json& v, const std::string& where, const std::string& field) {
  if (!v.is_number()) Fail(where, field, "expected a number, got " + std::string(v.type_name()));
  const double x = v.get<double>();
  if (!std::isfinite(x)) Fail(where, field, "not finite");
  return x;
}

// "schema", "version" and "model": the model's default preset.
MaterialPreset ParsePresetHeader(const json& j, const std::string& where) {
  if (!j.is_object()) Fail(where, "(top level)", "expected a JSON object");
  if (!j.contains("schema") || j["schema"] != "clothfit.preset")
    Fail(where, "schema", "expected \"clothfit.preset\"");
  if (!j.contains("version") || !j["version"].is_number_integer())
    Fail(where, "version", "missing or not an integer");
  if (j["version"].get<int>() != 1)
    Fail(where, "version", "unsupported version " + j["version"].dump() + " (this build reads 1)");
  if (!j.contains("model") || !j["model"].is_string())
    Fail(where, "model", "missing or not a string");
  MaterialPreset p;
  try {
    p = DefaultPreset(ParseModelKind(j["model"].get<std::string>()));
  } catch (const std::invalid_argument& e) {
    Fail(where, "model", e.what());
  }
  return p;
}

// The "cloth" object: the cloth model's variant and options.
void ParseClothOptions(const json& c, const std::string& where, cloth::Options* o) {
  if (!c.is_object()) Fail(where, "cloth", "expected an object");
  for (auto it = c.begin(); it != c.end(); ++it) {
    const std::string k = it.key();
    const std::string f = "cloth." + k;
    if (k == "variant") {
      const std::string v = it->is_string() ? it->get<std::string>() : "";
      if (v == "filament") o->variant = cloth::Variant::kFilament;
      else if (v == "seed-threejs") o->variant = cloth::Variant::kSeedThreejs;
      else Fail(where, f, "expected \"filament\" or \"seed-threejs\"");
    } else if (k == "sheen_default") {
      const std::string v = it->is_string() ? it->get<std::string>() : "";
      if (v == "explicit") o->sheen_default = cloth::SheenDefault::kExplicit;
      else if (v == "sqrt-base-color") o->sheen_default = cloth::SheenDefault::kSqrtBaseColor;
      else if (v == "white") o->sheen_default = cloth::SheenDefault::kWhite;
      else Fail(where, f, "expected \"explicit\", \"sqrt-base-color\" or \"white\"");
    } else if (k == "subsurface") {
      if (!it->is_boolean()) Fail(where, f, "expected true or false");
      o->subsurface = it->get<bool>();
    } else if (k == "platform") {
      const std::string v = it->is_string() ? it->get<std::string>() : "";
      if (v == "desktop") o->platform = Platform::kDesktop;
      else if (v == "mobile") o->platform = Platform::kMobile;
      else Fail(where, f, "expected \"desktop\" or \"mobile\"");
    } else {
      Fail(where, f, "unknown key (valid: variant, sheen_default, subsurface, platform)");
    }
  }
}

// "woven": {"yarn_lobe"}: the far-field yarn lobe (brdf/yarn_lobe.h FarField; docs/preset-format.md
// "The far-field yarn lobe"). Every key is required except "fabric"; sizes are checked before
// anything is read or allocated; the values' ranges by yarn_lobe::Validate.
std::shared_ptr<const yarn_lobe::FarField> ParseYarnLobe(const json& y, const std::string& where) {
  const std::string base = "woven.yarn_lobe";
  if (!y.is_object()) Fail(where, base, "expected an object");
  auto need = [&](const json& o, const std::string& field, const char* k) -> const json& {
    if (!o.contains(k)) Fail(where, field + "." + k, "missing");
    return o[k];
  };
  auto integer = [&](const json& v, const std::string& field, int lo, int hi) {
    if (!v.is_number_integer() || v.get<long long>() < lo || v.get<long long>() > hi ||
        (v.is_number_unsigned() && v.get<unsigned long long>() > (unsigned long long)hi))
      Fail(where, field, "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return int(v.get<long long>());
  };
  const json& model = need(y, base, "model");
  const bool micro = model.is_string() && model.get<std::string>() == "sadeghi-microcylinder";
  if (!model.is_string() || (!micro && model.get<std::string>() != "irawan-far-field"))
    Fail(where, base + ".model", "expected \"irawan-far-field\" or \"sadeghi-microcylinder\"");
  static const char* kKeys[] = {"model", "fabric", "nodes", "alpha", "beta", "h_width", "ss",
                                "scale", "groups", "ibl"};
  static const char* kMicroKeys[] = {"model", "fabric", "threads", "ibl"};
  for (auto it = y.begin(); it != y.end(); ++it) {
    bool known = false;
    if (micro)
      for (const char* k : kMicroKeys) known = known || it.key() == k;
    else
      for (const char* k : kKeys) known = known || it.key() == k;
    if (!known)
      Fail(where, base + "." + it.key(),
           micro ? "unknown key (valid for sadeghi-microcylinder: model, fabric, threads, ibl)"
                 : "unknown key (valid: model, fabric, nodes, alpha, beta, h_width, ss, scale, groups, ibl)");
  }
  auto f = std::make_shared<yarn_lobe::FarField>();
  if (y.contains("fabric")) {
    if (!y["fabric"].is_string()) Fail(where, base + ".fabric", "expected a string");
    f->fabric = y["fabric"].get<std::string>();
  }
  if (micro) {  // brdf/yarn_lobe.h FarField::Kind::kMicrocylinder
    f->kind = yarn_lobe::FarField::Kind::kMicrocylinder;
    const json& threads = need(y, base, "threads");
    if (!threads.is_array() || threads.size() != 2)
      Fail(where, base + ".threads", "expected an array of 2 threads");
    for (size_t j = 0; j < 2; ++j) {
      const json& t = threads[j];
      const std::string tf = base + ".threads[" + std::to_string(j) + "]";
      if (!t.is_object() || t.size() != 7)
        Fail(where, tf, "expected an object with eta, kd, gamma_s, gamma_v, a, volume_scale, offsets");
      microcylinder::Thread& th = f->threads[j];
      th.eta = Number(need(t, tf, "eta"), where, tf + ".eta");
      th.kd = Number(need(t, tf, "kd"), where, tf + ".kd");
      th.gamma_s = Number(need(t, tf, "gamma_s"), where, tf + ".gamma_s");
      th.gamma_v = Number(need(t, tf, "gamma_v"), where, tf + ".gamma_v");
      th.a = Number(need(t, tf, "a"), where, tf + ".a");
      th.volume_scale = Number(need(t, tf, "volume_scale"), where, tf + ".volume_scale");
      const json& off = need(t, tf, "offsets");
      if (!off.is_array() || off.empty() || off.size() > size_t(microcylinder::kMaxOffsets))
        Fail(where, tf + ".offsets", "expected an array of 1 to 64 numbers (degrees)");
      for (size_t k = 0; k < off.size(); ++k)
        th.offsets.push_back(Number(off[k], where, tf + ".offsets[" + std::to_string(k) + "]"));
    }
  } else {
    f->nodes = integer(need(y, base, "nodes"), base + ".nodes", 1, yarn_lobe::FarField::kMaxNodes);
    f->alpha = Number(need(y, base, "alpha"), where, base + ".alpha");
    f->beta = Number(need(y, base, "beta"), where, base + ".beta");
    f->h_width = Number(need(y, base, "h_width"), where, base + ".h_width");
    f->ss = Number(need(y, base, "ss"), where, base + ".ss");
    f->scale = Number(need(y, base, "scale"), where, base + ".scale");
    const json& groups = need(y, base, "groups");
    if (!groups.is_array() || groups.empty() || groups.size() > size_t(yarn_lobe::FarField::kMaxGroups))
      Fail(where, base + ".groups", "expected an array of 1 to " +
                                        std::to_string(yarn_lobe::FarField::kMaxGroups) + " groups");
    for (size_t i = 0; i < groups.size(); ++i) {
      const json& g = groups[i];
      const std::string gf = base + ".groups[" + std::to_string(i) + "]";
      if (!g.is_object() || g.size() != 10)
        Fail(where, gf, "expected an object with type, share, psi, umax, kappa, width, length, "
                        "across, along, area_factor");
      yarn_lobe::FarField::Group q;
      const json& type = need(g, gf, "type");
      if (!type.is_string() || (type.get<std::string>() != "warp" && type.get<std::string>() != "weft"))
        Fail(where, gf + ".type", "expected \"warp\" or \"weft\"");
      q.warp = type.get<std::string>() == "warp";
      q.share = Number(need(g, gf, "share"), where, gf + ".share");
      q.psi = Number(need(g, gf, "psi"), where, gf + ".psi");
      q.umax = Number(need(g, gf, "umax"), where, gf + ".umax");
      q.kappa = Number(need(g, gf, "kappa"), where, gf + ".kappa");
      q.width = Number(need(g, gf, "width"), where, gf + ".width");
      q.length = Number(need(g, gf, "length"), where, gf + ".length");
      q.across = Number(need(g, gf, "across"), where, gf + ".across");
      q.along = Number(need(g, gf, "along"), where, gf + ".along");
      q.area_factor = Number(need(g, gf, "area_factor"), where, gf + ".area_factor");
      f->groups.push_back(q);
    }
  }
  const json& ibl = need(y, base, "ibl");
  const std::string bf = base + ".ibl";
  if (!ibl.is_object() || ibl.size() != 3) Fail(where, bf, "expected an object with n_theta, n_phi, summary");
  f->ibl.n_theta = integer(need(ibl, bf, "n_theta"), bf + ".n_theta", 2, 64);
  f->ibl.n_phi = integer(need(ibl, bf, "n_phi"), bf + ".n_phi", 3, 128);
  const json& sum = need(ibl, bf, "summary");
  const size_t n = size_t(2) * size_t(f->ibl.n_theta) * size_t(f->ibl.n_phi) * 5;
  if (!sum.is_array() || sum.size() != n)
    Fail(where, bf + ".summary", "expected an array of 2 x n_theta x n_phi x 5 = " + std::to_string(n) +
                                     " numbers");
  f->ibl.ibl.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const double v = Number(sum[i], where, bf + ".summary[" + std::to_string(i) + "]");
    if (std::abs(v) > 1e30) Fail(where, bf + ".summary[" + std::to_string(i) + "]", "out of float range");
    f->ibl.ibl[i] = float(v);
  }
  try {
    yarn_lobe::Validate(*f, where + ": " + base);  // "<where>: woven.yarn_lobe.<field>: ..."
  } catch (const std::invalid_argument& e) {
    throw MaterialError(e.what());
  }
  return f;
}

// The "woven" object: brdf/woven.h woven::Options (the same keys and meaning as
// web/clothfit.js loadClothfitPreset).
void ParseWovenOptions(const json& w, const std::string& where, woven::Options* o,
                       std::shared_ptr<const yarn_lobe::FarField>* lobe) {
  if (!w.is_object()) Fail(where, "woven", "expected an object");
  for (auto it = w.begin(); it != w.end(); ++it) {
    const std::string k = it.key();
    const std::string f = "woven." + k;
    if (k == "yarn_layer") {
      const std::string v = it->is_string() ? it->get<std::string>() : "";
      if (v == "additive") o->yarn_layer = woven::YarnLayer::kAdditive;
      else if (v == "albedo-scaled") o->yarn_layer = woven::YarnLayer::kAlbedoScaled;
      else Fail(where, f, "expected \"additive\" or \"albedo-scaled\"");
    } else if (k == "tint_warp" || k == "tint_weft") {
      if (!it->is_array() || it->size() != 3) Fail(where, f, "expected an array of 3 numbers");
      Rgb<double> t;
      for (size_t c = 0; c < 3; ++c) {
        t[int(c)] = Number((*it)[c], where, f + "[" + std::to_string(c) + "]");
        if (t[int(c)] < 0.0) Fail(where, f + "[" + std::to_string(c) + "]", "must be >= 0");
      }
      (k == "tint_warp" ? o->tint_warp : o->tint_weft) = t;
    } else if (k == "ibl") {
      const std::string v = it->is_string() ? it->get<std::string>() : "";
      if (v == "split") o->ibl = woven::IblMode::kSplit;
      else if (v == "fis") o->ibl = woven::IblMode::kFis;
      else if (v == "bent") o->ibl = woven::IblMode::kBent;
      else Fail(where, f, "expected \"split\", \"fis\" or \"bent\"");
    } else if (k == "fis_taps" || k == "fis_diffuse_taps") {
      const int lo = k == "fis_taps" ? 1 : 0;
      if (!it->is_number_integer())
        Fail(where, f, "expected an integer in [" + std::to_string(lo) + ", " +
                           std::to_string(woven::kMaxFisTaps) + "]");
      // An unsigned JSON integer above LLONG_MAX would read as a negative long long: report it
      // as written.
      if (it->is_number_unsigned() && it->get<unsigned long long>() > (unsigned long long)woven::kMaxFisTaps)
        Fail(where, f, "expected an integer in [" + std::to_string(lo) + ", " +
                           std::to_string(woven::kMaxFisTaps) + "], got " +
                           std::to_string(it->get<unsigned long long>()));
      const long long t = it->get<long long>();
      if (t < lo || t > woven::kMaxFisTaps)
        Fail(where, f, "expected an integer in [" + std::to_string(lo) + ", " +
                           std::to_string(woven::kMaxFisTaps) + "], got " + std::to_string(t));
      (k == "fis_taps" ? o->fis_taps : o->fis_diffuse_taps) = int(t);
    } else if (k == "yarn_lobe") {
      *lobe = ParseYarnLobe(*it, where);
    } else {
      Fail(where, f,
           "unknown key (valid: yarn_layer, tint_warp, tint_weft, ibl, fis_taps, "
           "fis_diffuse_taps, yarn_lobe)");
    }
  }
  // The tap counts belong to filtered importance sampling (docs/preset-format.md).
  if (o->ibl != woven::IblMode::kFis)
    for (const char* k : {"fis_taps", "fis_diffuse_taps"})
      if (w.contains(k))
        Fail(where, std::string("woven.") + k, "only allowed with \"ibl\": \"fis\"");
  // The far-field lobe replaces the yarn lobes of the additive layer; its environment is its own
  // split sum (render/preview/preview.h PreviewOptions::yarn_lobe).
  if (*lobe && o->yarn_layer != woven::YarnLayer::kAdditive)
    Fail(where, "woven.yarn_lobe", "needs \"yarn_layer\": \"additive\"");
  if (*lobe && o->ibl != woven::IblMode::kSplit)
    Fail(where, "woven.yarn_lobe", "needs \"ibl\": \"split\" (the lobe's own split sum)");
}

// One entry of "parameters": looked up in the model's table, range-checked, stored in p->values.
void ParseParameter(const std::string& name, const json& value, const std::string& where,
                    MaterialPreset* p) {
  const auto table = ParameterTable(p->model);
  const std::string f = "parameters." + name;
  int off = 0;
  const ParamInfo* info = nullptr;
  for (const ParamInfo& q : table) {
    if (q.name == name) {
      info = &q;
      break;
    }
    off += q.size;
  }
  if (!info) {
    std::string valid;
    for (const ParamInfo& q : table) valid += (valid.empty() ? "" : ", ") + std::string(q.name);
    Fail(where, f, "unknown parameter for model " + ToString(p->model) + " (valid: " + valid + ")");
  }
  std::vector<double> v;
  if (info->size == 1) {
    v.push_back(Number(value, where, f));
  } else {
    if (!value.is_array() || value.size() != size_t(info->size))
      Fail(where, f, "expected an array of " + std::to_string(info->size) + " numbers");
    for (size_t c = 0; c < value.size(); ++c)
      v.push_back(Number(value[c], where, f + "[" + std::to_string(c) + "]"));
  }
  const auto [lo, hi] = PresetRange(*info);
  for (size_t c = 0; c < v.size(); ++c) {
    if (v[c] < lo || v[c] > hi) {
      std::ostringstream os;
      os << "value " << v[c] << " outside [" << lo << ", " << hi << "]";
      Fail(where, info->size == 1 ? f : f + "[" + std::to_string(c) + "]", os.str());
    }
    p->values[size_t(off) + c] = v[c];
  }
}

json YarnLobeToJson(const yarn_lobe::FarField& f) {
  json summary = json::array();
  for (float v : f.ibl.ibl) summary.push_back(double(v));
  const json ibl = {{"n_theta", f.ibl.n_theta}, {"n_phi", f.ibl.n_phi}, {"summary", summary}};
  if (f.kind == yarn_lobe::FarField::Kind::kMicrocylinder) {
    json threads = json::array();
    for (const microcylinder::Thread& th : f.threads)
      threads.push_back({{"eta", th.eta}, {"kd", th.kd}, {"gamma_s", th.gamma_s},
                         {"gamma_v", th.gamma_v}, {"a", th.a}, {"volume_scale", th.volume_scale},
                         {"offsets", th.offsets}});
    return {{"model", "sadeghi-microcylinder"}, {"fabric", f.fabric}, {"threads", threads}, {"ibl", ibl}};
  }
  json groups = json::array();
  for (const yarn_lobe::FarField::Group& g : f.groups)
    groups.push_back({{"type", g.warp ? "warp" : "weft"}, {"share", g.share}, {"psi", g.psi},
                      {"umax", g.umax}, {"kappa", g.kappa}, {"width", g.width},
                      {"length", g.length}, {"across", g.across}, {"along", g.along},
                      {"area_factor", g.area_factor}});
  return {{"model", "irawan-far-field"}, {"fabric", f.fabric}, {"nodes", f.nodes},
          {"alpha", f.alpha}, {"beta", f.beta}, {"h_width", f.h_width}, {"ss", f.ss},
          {"scale", f.scale}, {"groups", groups}, {"ibl", ibl}};
}

}  // namespace

MaterialPreset ParsePreset(const json& j, const std::string& where) {
  MaterialPreset p = ParsePresetHeader(j, where);
  if (j.contains("cloth")) {
    if (p.model != ModelKind::kCloth) Fail(where, "cloth", "only allowed with model \"cloth\"");
    ParseClothOptions(j["cloth"], where, &p.cloth);
  }
  if (j.contains("woven")) {
    if (p.model != ModelKind::kWoven) Fail(where, "woven", "only allowed with model \"woven\"");
    ParseWovenOptions(j["woven"], where, &p.woven, &p.yarn_lobe);
  }
  if (!j.contains("parameters") || !j["parameters"].is_object())
    Fail(where, "parameters", "missing or not an object");
  for (auto it = j["parameters"].begin(); it != j["parameters"].end(); ++it) {
    ParseParameter(it.key(), *it, where, &p);
  }
  // Keys this build does not interpret are kept and written back (PresetToJson): the ones other
  // parts of clothfit and web/clothfit.js read (kCarried), and any other key, so that a preset
  // written by a newer build survives a round trip through this one. A key that is almost a
  // known one ("weave_map", "Woven", "paramters") is refused instead: silently kept, it would
  // draw the material without what the author meant (the weave maps, the woven options).
  static const char* kInterpreted[] = {"schema", "version", "model", "engine", "cloth", "woven",
                                       "conventions", "parameters"};
  static const char* kCarried[] = {"fit", "provenance", "weave_maps", "convert", "maps",
                                   "side", "name"};
  for (auto it = j.begin(); it != j.end(); ++it) {
    bool known = false;
    for (const char* k : kInterpreted) known = known || it.key() == k;
    if (known) continue;
    for (const char* k : kCarried) known = known || it.key() == k;
    if (!known) {
      for (const char* k : kInterpreted) CheckNotNearMiss(it.key(), k, where);
      for (const char* k : kCarried) CheckNotNearMiss(it.key(), k, where);
    }
    p.extra[it.key()] = *it;
  }
  return p;
}

MaterialPreset ReadPreset(const std::string& path) {
  // Bounded read, then the nesting limit before the DOM: unknown keys are kept in `extra` and
  // copied and dumped recursively (docs/reliability.md).
  std::string text;
  try {
    text = limits::ReadFileBounded(path, limits::kMaxJsonFileBytes, "material preset");
    limits::CheckJsonDepth(text, path);
  } catch (const limits::InputError& e) {
    throw MaterialError(e.what());
  }
  json j;
  try {
    j = json::parse(text);
  } catch (const json::parse_error& e) {
    // e.byte is the offset; report line and column.
    size_t line = 1, col = 1;
    for (size_t i = 0; i + 1 < e.byte && i < text.size(); ++i) {
      if (text[i] == '\n') {
        ++line;
        col = 1;
      } else {
        ++col;
      }
    }
    throw MaterialError(path + ":" + std::to_string(line) + ":" + std::to_string(col) +
                        ": malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  } catch (const json::out_of_range& e) {  // 406: a number beyond double (1e400) while parsing
    throw MaterialError(path + ": malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  }
  return ParsePreset(j, path);
}

json PresetToJson(const MaterialPreset& p) {
  json j = json::object();
  j["schema"] = "clothfit.preset";
  j["version"] = 1;
  j["model"] = ToString(p.model);
  j["engine"] = EngineOf(p.model);
  if (p.model == ModelKind::kCloth) {
    j["cloth"] = {{"variant", std::string(cloth::ToString(p.cloth.variant))},
                  {"sheen_default", std::string(cloth::ToString(p.cloth.sheen_default))},
                  {"subsurface", p.cloth.subsurface},
                  {"platform", p.cloth.platform == Platform::kMobile ? "mobile" : "desktop"}};
  }
  if (p.model == ModelKind::kWoven) {
    auto rgb = [](const Rgb<double>& c) { return json::array({c[0], c[1], c[2]}); };
    j["woven"] = {{"yarn_layer", std::string(woven::ToString(p.woven.yarn_layer))},
                  {"tint_warp", rgb(p.woven.tint_warp)},
                  {"tint_weft", rgb(p.woven.tint_weft)},
                  {"ibl", std::string(woven::ToString(p.woven.ibl))}};
    if (p.woven.ibl == woven::IblMode::kFis) {
      j["woven"]["fis_taps"] = p.woven.fis_taps;
      j["woven"]["fis_diffuse_taps"] = p.woven.fis_diffuse_taps;
    }
    if (p.yarn_lobe) j["woven"]["yarn_lobe"] = YarnLobeToJson(*p.yarn_lobe);
  }
  j["conventions"] = {{"colour_space", "linear sRGB (Rec.709 primaries), not gamma-encoded"},
                      {"roughness", "perceptual r in [0, 1]; the models use alpha = r^2"}};
  if (p.model == ModelKind::kWoven)
    j["conventions"]["diffuse_roughness"] =
        "sigma of Fujii's improved Oren-Nayar diffuse, used as is (not squared); 0 = Lambert "
        "(brdf/woven.h)";
  json params = json::object();
  int off = 0;
  for (const ParamInfo& info : ParameterTable(p.model)) {
    if (info.size == 1) {
      params[std::string(info.name)] = p.values[size_t(off)];
    } else {
      params[std::string(info.name)] = json::array(
          {p.values[size_t(off)], p.values[size_t(off) + 1], p.values[size_t(off) + 2]});
    }
    off += info.size;
  }
  j["parameters"] = params;
  for (auto it = p.extra.begin(); it != p.extra.end(); ++it) j[it.key()] = *it;
  return j;
}

void WritePreset(const std::string& path, const MaterialPreset& p) {
  for (double v : p.values)
    if (!std::isfinite(v)) throw MaterialError(path + ": refusing to write a non-finite parameter");
  io::WriteTextAtomic(path, PresetToJson(p).dump(2) + "\n");
}

std::string ResolvePresetRelativeUri(const std::string& preset_path, const std::string& field,
                               const std::string& uri) {
  namespace fs = std::filesystem;
  const std::string where = limits::EscapeForMessage(preset_path, 400) + ": field " + field + ": ";
  const std::string shown = "'" + limits::EscapeForMessage(uri, 200) + "'";
  if (uri.empty()) throw MaterialError(where + "empty path");
  for (unsigned char c : uri)
    if (c < 0x20 || c == 0x7F) throw MaterialError(where + shown + " contains a control byte");
  if (uri.find("://") != std::string::npos || uri.rfind("data:", 0) == 0 ||
      uri.rfind("file:", 0) == 0)
    throw MaterialError(where + shown + " is a URI with a scheme; expected a path relative to "
                        "the preset's directory");
  const fs::path u(uri);
  if (u.is_absolute() || u.has_root_name() || u.has_root_directory())
    throw MaterialError(where + shown + " is an absolute path; \"uri\" is relative to the "
                        "preset's directory (an absolute path goes in \"file\", read only "
                        "without a \"uri\")");
  const fs::path norm = u.lexically_normal();
  if (norm.empty() || *norm.begin() == "..")
    throw MaterialError(where + shown + " escapes the preset's directory (\"..\"); the maps "
                        "must lie in the preset's directory or below it");
  std::error_code ec;
  const fs::path dir = fs::absolute(fs::path(preset_path), ec).parent_path();
  if (ec) throw MaterialError(where + "cannot make the preset's path absolute: " + ec.message());
  const fs::path joined = (dir / norm).lexically_normal();
  if (!fs::exists(joined, ec))
    throw MaterialError(where + shown + ": no such file (looked for " +
                        limits::EscapeForMessage(joined.string(), 400) + ")");
  const fs::path canon = fs::weakly_canonical(joined, ec);
  const fs::path root = ec ? fs::path() : fs::weakly_canonical(dir, ec);
  if (ec) throw MaterialError(where + shown + ": " + ec.message());
  if (!limits::IsInside(canon, root))
    throw MaterialError(where + shown + " resolves (through a symbolic link) outside the "
                        "preset's directory");
  if (!fs::is_regular_file(canon, ec))
    throw MaterialError(where + shown + ": not a regular file");
  return canon.string();
}


}  // namespace clothfit::render
