// fit/yarn_farfield.cpp: see yarn_farfield.h.
#include "fit/yarn_farfield.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <algorithm>
#include <stdexcept>


#include <chrono>

#include "brdf/yarn_lobe.h"
#include "fit/image_fit.h"
#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/reference/sadeghi.h"
#include "render/reference/weave_pattern.h"
#include "render/scene/sampler.h"

namespace clothfit::fit {

namespace {

uint64_t Mix(uint64_t z) { return render::Mix64(z); }  // SplitMix64 finaliser
uint64_t Bits(double x) {
  uint64_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}
double Unit(uint64_t z) { return double(z >> 11) * (1.0 / 9007199254740992.0); }

}  // namespace

struct YarnFarField::Impl {
  render::Fabric fabric;
  const render::IrawanBsdf* irawan = nullptr;
  int side = 4;
  std::string path;
  struct Group {
    int yarn = 0;         // a representative yarn index
    double share = 0.0;   // its group's fraction of the tile's cells
    double across = 0.5, along = 0.5;  // half extents of its segments' cells (cells)
  };
  std::vector<Group> groups;
};

YarnFarField::YarnFarField(const std::string& fabric_path, int positions)
    : impl_(std::make_unique<Impl>()) {
  const int side = int(std::lround(std::sqrt(double(std::max(positions, 0)))));
  if (positions < 1 || positions > 4096 || side * side != positions)
    throw std::invalid_argument("yarn far-field: positions " + std::to_string(positions) +
                                " is not a square in [1, 4096]");
  impl_->fabric = render::LoadFabric(fabric_path);
  impl_->irawan = dynamic_cast<const render::IrawanBsdf*>(impl_->fabric.bsdf.get());
  if (!impl_->irawan)
    throw std::invalid_argument(fabric_path + ": model '" + impl_->fabric.model +
                                "' has no yarns: the far-field yarn lobe needs an irawan fabric");
  impl_->side = side;
  impl_->path = fabric_path;
  // Groups of identical yarns and their share of the tile's cells.
  const auto& pat = impl_->irawan->pattern();
  // Each yarn id is one rectangle of cells centred on its segment centre, as the renderer
  // derives them (weave_pattern.h DeriveSegmentCentres): columns run along the warp's across
  // axis (draft X), rows along Y.
  render::WeavePattern copy = pat;
  const std::vector<render::SegmentCells> rect =
      render::DeriveSegmentCentres(&copy, "yarn far-field (" + fabric_path + ")");
  const double total = double(pat.tile_width) * double(pat.tile_height);
  for (size_t i = 0; i < pat.yarns.size() && i < rect.size(); ++i) {
    const render::Yarn& y = pat.yarns[i];
    const double half_x = 0.5 * (rect[i].col1 - rect[i].col0 + 1);
    const double half_y = 0.5 * (rect[i].row1 - rect[i].row0 + 1);
    const double share = 4.0 * half_x * half_y / total;  // the rectangle's cells
    const bool warp = y.type == render::YarnType::kWarp;
    const double across = warp ? half_x : half_y, along = warp ? half_y : half_x;
    bool merged = false;
    for (Impl::Group& g : impl_->groups) {
      const render::Yarn& z = pat.yarns[size_t(g.yarn)];
      if (z.type == y.type && z.psi == y.psi && z.umax == y.umax && z.kappa == y.kappa &&
          z.width == y.width && z.length == y.length && g.across == across && g.along == along) {
        g.share += share;
        merged = true;
        break;
      }
    }
    if (!merged) impl_->groups.push_back({int(i), share, across, along});
  }
}

yarn_lobe::FarField YarnFarField::Description(int nodes, int table_theta) const {
  if (nodes < 1 || nodes > yarn_lobe::FarField::kMaxNodes)
    throw std::invalid_argument("yarn far-field: quadrature nodes " + std::to_string(nodes) +
                                " not in [1, 64]");
  const render::IrawanBsdf& b = *impl_->irawan;
  const auto& pat = b.pattern();
  yarn_lobe::FarField f;
  f.fabric = impl_->path;
  f.nodes = nodes;
  f.alpha = pat.alpha;
  f.beta = pat.beta;
  f.h_width = pat.h_width;
  f.ss = pat.ss;
  f.scale = (pat.fineness > 0.0 ? 1.0 - std::exp(-10.0) : 1.0) * b.specular_normalisation();
  for (const Impl::Group& g : impl_->groups) {
    const render::Yarn& y = pat.yarns[size_t(g.yarn)];
    yarn_lobe::FarField::Group q;
    q.warp = y.type == render::YarnType::kWarp;
    q.share = g.share;
    q.psi = y.psi;
    q.umax = y.umax;
    q.kappa = y.kappa;
    q.width = y.width;
    q.length = y.length;
    q.across = g.across;
    q.along = g.along;
    q.area_factor = (pat.warp_area + pat.weft_area) / (q.warp ? pat.warp_area : pat.weft_area);
    f.groups.push_back(q);
  }
  if (table_theta > 0) {
    const yarn_lobe::Lobe lobe(f);
    f.ibl = yarn_lobe::Bake([&lobe](const Vec3<double>& wo, const Vec3<double>& wi,
                                    double out[2]) { lobe.Eval(wo, wi, out); },
                            table_theta, 2 * table_theta, false);
  }
  return f;
}

void YarnFarField::EvalQuadrature(const Vec3<double>& wo, const Vec3<double>& wi, double out[2],
                                  int nodes) const {
  yarn_lobe::Lobe(Description(nodes, 0)).Eval(wo, wi, out);
}

YarnFarField::~YarnFarField() = default;

void YarnFarField::Eval(const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) const {
  out[0] = out[1] = 0.0;
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return;
  const render::IrawanBsdf& b = *impl_->irawan;
  const auto& pat = b.pattern();
  uint64_t h = Mix(Bits(wo.x) ^ Mix(Bits(wo.y) ^ Mix(Bits(wo.z) ^ Mix(Bits(wi.x) ^
                   Mix(Bits(wi.y) ^ Mix(Bits(wi.z)))))));
  const int S = impl_->side;
  const double norm = b.specular_normalisation() / double(S * S);
  // One tile in uv: 1 / repeat along u and v.
  const double tu = 1.0 / b.repeat_u(), tv = 1.0 / b.repeat_v();
  for (int j = 0; j < S; ++j) {
    for (int i = 0; i < S; ++i) {
      // each point in its own random tile: the fineness intensity (hashed per fabric cell,
      // exponentially distributed) varies from tile to tile
      h = Mix(h);
      const double tile_u = std::floor(Unit(h) * 1024.0);
      h = Mix(h);
      const double tile_v = std::floor(Unit(h) * 1024.0);
      h = Mix(h);
      const double fx = (i + Unit(h)) / S;
      h = Mix(h);
      const double fy = (j + Unit(h)) / S;
      const render::IrawanPoint p = b.Locate({(tile_u + fx) * tu, (tile_v + fy) * tv});
      const double s = b.SpecularIntegrand(p, wo, wi) * p.intensity * norm;
      out[pat.yarns[size_t(p.yarn)].type == render::YarnType::kWarp ? 0 : 1] += s;
    }
  }
}

double YarnFarField::WarpAlbedoShare(int pairs) const {
  double sum[2] = {0.0, 0.0};
  uint64_t h = 0x5EEDull;
  for (int k = 0; k < pairs; ++k) {
    auto cosine = [&]() {
      h = Mix(h);
      const double u1 = Unit(h);
      h = Mix(h);
      return render::SampleCosineHemisphere({u1, Unit(h)});
    };
    const Vec3<double> wo = cosine(), wi = cosine();
    double v[2];
    Eval(wo, wi, v);
    sum[0] += v[0];
    sum[1] += v[1];
  }
  return sum[0] + sum[1] > 0.0 ? sum[0] / (sum[0] + sum[1]) : 0.5;
}

yarn_table::Table YarnFarField::Bake(int n_theta, int n_phi, int jitter, int quadrature_nodes) const {
  if (n_theta < 2 || n_theta > 64 || n_phi < 3 || n_phi > 128)
    throw std::invalid_argument("yarn table: resolution " + std::to_string(n_theta) + " x " +
                                std::to_string(n_phi) + " not in [2, 64] x [3, 128]");
  if (quadrature_nodes > 0) {
    const yarn_lobe::Lobe lobe(Description(quadrature_nodes, 0));
    return yarn_lobe::Bake([&lobe](const Vec3<double>& wo, const Vec3<double>& wi,
                                   double out[2]) { lobe.Eval(wo, wi, out); },
                           n_theta, n_phi, true);
  }
  if (jitter <= 0)
    return yarn_lobe::Bake([this](const Vec3<double>& wo, const Vec3<double>& wi,
                                  double out[2]) { Eval(wo, wi, out); },
                           n_theta, n_phi, true);
  // The bin average: wo and wi jittered within their bins, hashed on the pair of bins.
  const double dth = 0.5 * kPi / n_theta, dph = 2.0 * kPi / n_phi;
  auto bin_of = [&](const Vec3<double>& d) {
    const int it = std::clamp(int(std::acos(std::clamp(d.z, -1.0, 1.0)) / dth), 0, n_theta - 1);
    double ph = std::atan2(d.y, d.x);
    if (ph < 0.0) ph += 2.0 * kPi;
    const int ip = std::clamp(int(ph / dph), 0, n_phi - 1);
    return size_t(it) * size_t(n_phi) + size_t(ip);
  };
  return yarn_lobe::Bake(
      [&, this](const Vec3<double>& wo, const Vec3<double>& wi, double v[2]) {
        v[0] = v[1] = 0.0;
        uint64_t h = Mix(bin_of(wo) * 0x9E3779B97F4A7C15ull + bin_of(wi));
        auto jit = [&](size_t bin) {
          const int it = int(bin) / n_phi, ip = int(bin) % n_phi;
          h = Mix(h);
          const double th = (it + Unit(h)) * dth;
          h = Mix(h);
          const double ph = (ip + Unit(h)) * dph;
          return Vec3<double>(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
        };
        const size_t bo = bin_of(wo), bi = bin_of(wi);
        for (int j = 0; j < jitter; ++j) {
          double q[2];
          Eval(jit(bo), jit(bi), q);
          v[0] += q[0] / jitter;
          v[1] += q[1] / jitter;
        }
      },
      n_theta, n_phi, true);
}

std::string YarnFarField::Describe() const {
  return "irawan far-field of " + impl_->path + " (" + impl_->irawan->Name() + ", " +
         std::to_string(impl_->side * impl_->side) + " positions per evaluation)";
}

nlohmann::json ToJson(const YarnLobeSettings& s) {
  return {{"mode", s.mode},           {"fabric", s.fabric},           {"positions", s.positions},
          {"nodes", s.nodes},         {"table_theta", s.table_theta}, {"table_jitter", s.table_jitter},
          {"ibl", s.ibl}};
}

YarnLobeSettings YarnLobeSettingsFromJson(const nlohmann::json& j, const std::string& where) {
  if (!j.is_object()) throw std::runtime_error(where + ": expected an object");
  YarnLobeSettings s;
  auto str = [&](const char* k) {
    if (!j.contains(k) || !j[k].is_string())
      throw std::runtime_error(where + "." + k + ": expected a string");
    return j[k].get<std::string>();
  };
  auto num = [&](const char* k, int lo, int hi) {
    if (!j.contains(k) || !j[k].is_number_integer() || j[k].get<int64_t>() < lo ||
        j[k].get<int64_t>() > hi)
      throw std::runtime_error(where + "." + k + ": expected an integer in [" + std::to_string(lo) +
                               ", " + std::to_string(hi) + "]");
    return int(j[k].get<int64_t>());
  };
  s.mode = str("mode");
  if (s.mode != "farfield" && s.mode != "table" && s.mode != "farfield-split" &&
      s.mode != "quadrature")
    throw std::runtime_error(where + ".mode: expected \"farfield\", \"table\", "
                             "\"farfield-split\" or \"quadrature\"");
  s.fabric = str("fabric");
  s.positions = num("positions", 1, 4096);
  s.nodes = num("nodes", 1, 64);
  s.table_theta = num("table_theta", 2, 64);
  s.table_jitter = num("table_jitter", 0, 4096);
  if (j.contains("ibl")) {
    s.ibl = str("ibl");
    if (s.ibl != "summary" && s.ibl != "bins")
      throw std::runtime_error(where + ".ibl: expected \"summary\" or \"bins\"");
  }
  return s;
}

void MicrocylinderStart(render::MaterialPreset* p) {
  auto set = [p](const char* name, std::initializer_list<double> v) {
    const int at = p->Offset(name);
    int k = 0;
    for (double x : v) p->values[size_t(at + k++)] = x;
  };
  set("specular_color", {1.0, 1.0, 1.0});
  set("warp_share", {0.5});
  set("base_color", {0.0, 0.0, 0.0});
  set("sheen_color", {0.0, 0.0, 0.0});
}

namespace {
void LockLobeIgnored(FitOptions* o) {
  for (const char* n : {"roughness", "anisotropy", "twist", "specular_f0", "forward_scattering"})
    if (std::find(o->locked.begin(), o->locked.end(), n) == o->locked.end()) o->locked.push_back(n);
}
}  // namespace

namespace {
// The Sadeghi fabric behind fabric_path, and the lobe's one volume colour: the brighter
// thread's albedo (*ref, *first = thread 0 is it) and the other's strength k relative to it.
// Returns "" or why the lobe cannot carry the fabric.
std::string OneVolumeColour(const std::string& fabric_path, const render::Fabric& fabric,
                            render::Rgbd* ref_out, bool* first_out, double* k_out) {
  const auto* sadeghi = dynamic_cast<const render::SadeghiBsdf*>(fabric.bsdf.get());
  if (!sadeghi)
    return fabric_path + ": model '" + fabric.model +
           "' is not a sadeghi fabric (the microcylinder lobe)";
  const render::SadeghiFabric& sf = sadeghi->fabric();
  const render::Rgbd& a0 = sf.thread[0].albedo;
  const render::Rgbd& a1 = sf.thread[1].albedo;
  const bool first = a0[0] + a0[1] + a0[2] >= a1[0] + a1[1] + a1[2];
  const render::Rgbd& ref = first ? a0 : a1;
  const render::Rgbd& other = first ? a1 : a0;
  const double rsum = ref[0] + ref[1] + ref[2];
  const double k = rsum > 0.0 ? (other[0] + other[1] + other[2]) / rsum : 0.0;
  for (int c = 0; c < 3; ++c)
    if (std::abs(other[c] - k * ref[c]) > 1e-9 * std::max(1.0, ref[c]))
      return fabric_path + ": the two threads of '" + sf.name +
             "' differ in hue, not only in strength; the microcylinder lobe carries one volume "
             "colour (woven's tint_weft)";
  if (ref_out) *ref_out = ref;
  if (first_out) *first_out = first;
  if (k_out) *k_out = k;
  return "";
}
}  // namespace

std::string MicrocylinderRefusal(const std::string& fabric_path) {
  return OneVolumeColour(fabric_path, render::LoadFabric(fabric_path), nullptr, nullptr, nullptr);
}

MicrocylinderLobe MicrocylinderDescription(const std::string& fabric_path, int table_theta) {
  const render::Fabric fabric = render::LoadFabric(fabric_path);
  render::Rgbd ref;
  bool first = true;
  double k = 0.0;
  const std::string why = OneVolumeColour(fabric_path, fabric, &ref, &first, &k);
  if (!why.empty()) throw std::invalid_argument(why);
  const render::SadeghiFabric& sf =
      dynamic_cast<const render::SadeghiBsdf*>(fabric.bsdf.get())->fabric();
  MicrocylinderLobe out;
  out.lobe.kind = yarn_lobe::FarField::Kind::kMicrocylinder;
  out.lobe.fabric = fabric_path;
  double gamma_min = 90.0;
  for (int j = 0; j < 2; ++j) {
    const render::SadeghiThread& t = sf.thread[j];
    out.lobe.threads[j] = render::MicrocylinderThread(t, (j == 0) == first ? 1.0 : k);
    gamma_min = std::min({gamma_min, t.gamma_s, t.gamma_v});
  }
  for (int c = 0; c < 3; ++c) out.albedo[c] = ref[c];
  // The summary's wi sums at a spacing of at most the narrowest Gaussian's standard deviation
  // (satin's surface lobe is 2.5 deg wide; a 16-bin table's bins are 5.6 deg).
  const double bin = 90.0 / double(table_theta);
  out.wi_sub = std::clamp(int(std::ceil(bin / gamma_min)), 1, 8);
  const yarn_lobe::Lobe lobe(out.lobe);
  out.lobe.ibl = yarn_lobe::Bake([&lobe](const Vec3<double>& wo, const Vec3<double>& wi,
                                         double v[2]) { lobe.Eval(wo, wi, v); },
                                 table_theta, 2 * table_theta, false, out.wi_sub);
  return out;
}

std::string ApplyPresetYarnLobe(const YarnLobeSettings& s, FitOptions* o) {
  if (o->start.woven.yarn_layer != woven::YarnLayer::kAdditive)
    throw std::invalid_argument("yarn lobe: the far-field lobe needs the additive yarn layer");
  const auto t0 = std::chrono::steady_clock::now();
  if (render::LoadFabric(s.fabric).model == "sadeghi") {  // session 19: the fibres' own BSDF
    MicrocylinderLobe m = MicrocylinderDescription(s.fabric, s.table_theta);
    o->start.yarn_lobe = std::make_shared<const yarn_lobe::FarField>(std::move(m.lobe));
    o->start.woven.ibl = woven::IblMode::kSplit;
    // out[0] (surface) white, out[1] (volume) in the threads' colour: ks = 1 and m = 0.5 draw
    // the reference BSDF exactly, so the fit starts there (MicrocylinderStart).
    o->start.woven.tint_warp = Rgb<double>(1.0, 1.0, 1.0);
    o->start.woven.tint_weft = m.albedo;
    MicrocylinderStart(&o->start);
    LockLobeIgnored(o);
    char buf[240];
    std::snprintf(buf, sizeof buf,
                  "yarn lobe: the microcylinder lobe of %s (surface white, volume albedo %.4g %.4g "
                  "%.4g as tint_weft), environment summary %d x %d (wi %dx finer) baked in %.2f s",
                  s.fabric.c_str(), m.albedo[0], m.albedo[1], m.albedo[2], s.table_theta,
                  2 * s.table_theta, m.wi_sub,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    return buf;
  }
  const YarnFarField ff(s.fabric, s.positions);
  o->start.yarn_lobe = std::make_shared<const yarn_lobe::FarField>(ff.Description(s.nodes, s.table_theta));
  o->start.woven.ibl = woven::IblMode::kSplit;
  LockLobeIgnored(o);
  char buf[200];
  std::snprintf(buf, sizeof buf,
                "yarn lobe: the far-field lobe of %s, %zu yarn groups x %d nodes, environment "
                "summary %d x %d baked in %.2f s",
                s.fabric.c_str(), o->start.yarn_lobe->groups.size(), s.nodes, s.table_theta,
                2 * s.table_theta,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return buf;
}

std::string ApplyYarnLobe(const YarnLobeSettings& s, FitOptions* o) {
  if (s.mode != "farfield" && s.mode != "table" && s.mode != "farfield-split" &&
      s.mode != "quadrature")
    throw std::invalid_argument("yarn lobe: unknown mode '" + s.mode +
                                "' (farfield, table, farfield-split, quadrature)");
  if (s.ibl != "summary" && s.ibl != "bins")
    throw std::invalid_argument("yarn lobe: ibl '" + s.ibl + "' (summary, bins)");
  const double D = double(s.table_theta) * 2.0 * s.table_theta;
  if (s.mode != "farfield" &&
      D * D * std::max(1, s.table_jitter) * (s.mode == "quadrature" ? s.nodes : s.positions) > 2e10)
    throw std::invalid_argument("yarn lobe: a " + std::to_string(s.table_theta) + " x " +
                                std::to_string(2 * s.table_theta) +
                                " table bake would take more than 2e10 lobe evaluations; fewer "
                                "bins, positions or jitter");
  o->yarn_far_field = std::make_shared<const YarnFarField>(s.fabric, s.positions);
  o->yarn_quadrature_nodes = s.mode == "quadrature" ? s.nodes : 0;
  o->yarn_table_ibl_only = s.mode == "farfield-split" || s.mode == "quadrature";
  o->yarn_table.reset();
  o->yarn_ibl_bins = s.ibl == "bins";
  std::string line;
  if (s.mode != "farfield") {
    const auto t0 = std::chrono::steady_clock::now();
    o->yarn_table = std::make_shared<const yarn_table::Table>(o->yarn_far_field->Bake(
        s.table_theta, 2 * s.table_theta, s.table_jitter, o->yarn_quadrature_nodes));
    char buf[160];
    std::snprintf(buf, sizeof buf, "yarn table %d x %d per direction baked in %.2f s (", s.table_theta,
                  2 * s.table_theta,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    line = buf + o->yarn_far_field->Describe() + ")";
  }
  LockLobeIgnored(o);
  return line;
}

}  // namespace clothfit::fit
