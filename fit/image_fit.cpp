#include "fit/image_fit.h"
#include "fit/yarn_farfield.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <span>
#include <string_view>

#include "fit/metrics/reference_halves.h"
#include "fit/reference.h"
#include "render/scene/embree_scene.h"
#include "render/scene/image_io.h"

namespace clothfit::fit {
namespace {

// Jacobians come from one dual-number evaluation of the preview with N derivative slots, N the
// smallest instantiated width (render/preview/preview.cpp) holding the free scalars: the cost
// of Jet arithmetic grows with N, and most models have fewer than 10 free scalars
// (standard 4; cloth, physical-sheen, gltf-sheen 7-8; woven stages 10).
//
// Colour packing (docs/fitting.md, "Fit speed"): a free RGB block whose channel c enters only
// the preview's channel c (base_color of every model; cloth's sheen and subsurface colours;
// woven's specular_color with additive yarn layering; NOT a sheen colour under albedo scaling,
// whose max3 couples the channels) needs one derivative slot, not three: its three scalars
// share a slot and output channel c's derivative in that slot is d(out_c)/d(x_c). The block
// means are linear in the pixels, so they keep this; the display transform may mix channels
// (AgX, Neutral), so its 3 x 3 Jacobian is applied per block before the residuals
// (PreviewCost::PackedResiduals).
constexpr int kJetWidths[] = {4, 6, 8, 10};
constexpr int kMaxJetWidth = 10;

// The space transform, templated so Jets flow through it.
template <typename T>
Rgb<T> Transform(const Rgb<T>& lin, Space space, render::ToneMapping op, double exposure) {
  switch (space) {
    case Space::kDisplay: return render::ToDisplay(lin, op, exposure);
    case Space::kLinear: return lin;
    case Space::kLog: {
      using std::log;
      Rgb<T> out;
      for (int c = 0; c < 3; ++c) out[c] = log(Max(lin[c], Const<T>(0.0)) + Const<T>(1e-3));
      return out;
    }
  }
  return lin;
}

struct SceneData {
  std::string scene_path, reference_path;
  std::unique_ptr<render::PreviewCache> cache;  // only the pixels the blocks use
  std::vector<int> block_begin;                 // CSR over cache pixels
  std::vector<double> pixel_weight;             // reference coverage weight of each pixel
  std::vector<double> block_weight;             // sum of pixel_weight per block
  std::vector<Rgb<double>> ref_t;               // transformed reference block means
  std::vector<Rgb<double>> weight;              // per block and channel
  std::vector<Rgb<double>> second_t;            // transformed second-reference block means
  // Without a second reference, from the reference's half channels: transformed block means
  // of the halves A and B, and sqrt(kA (K - kA)) / K (fit/metrics/reference_halves.h).
  std::vector<Rgb<double>> half_a_t, half_b_t;
  double half_scale = 0.0;
  int dropped_preview = 0, dropped_coverage = 0;
  render::ToneMapping op = render::ToneMapping::kLinear;
  double exposure = 1.0;
  Space space = Space::kDisplay;
  int blocks() const { return int(block_begin.size()) - 1; }
};

// The preview options of a fit's previews for the preset `p`: model, cloth and woven options,
// weave maps, IBL engine, sun, and the measurement settings (exact IBL, sheen tilt,
// visibility, far-field yarn lobe). The caller adds the sample mask and footprint.
render::PreviewOptions PreviewOptionsFor(const FitOptions& opt, const render::MaterialPreset& p) {
  render::PreviewOptions po;
  po.model = p.model;
  po.cloth = p.cloth;
  po.woven = render::PreviewWovenOptions(p);  // yarn layering, tints, IBL mode (split / FIS) and taps
  // "woven": {"yarn_lobe"}; a measurement mode (yarn_far_field / yarn_table) replaces it below
  if (!opt.yarn_far_field && !opt.yarn_table) render::ApplyPresetYarnLobe(p, &po);
  po.ibl_engine = opt.ibl_engine;
  po.weave_maps = render::LoadPresetWeaveMaps(p);  // woven weave maps (null: none)
  po.exact_ibl_samples = opt.exact_ibl_samples;
  po.exact_ibl_seed = opt.exact_ibl_seed;
  po.exact_irradiance_samples = opt.exact_irradiance_samples;
  po.sheen_tilt_degrees = opt.sheen_tilt_degrees;
  po.shadows = opt.shadows;
  po.visibility = opt.visibility;
  po.card_visibility = opt.card_visibility;
  // a light map's bounce off the fabric: the material's own albedo unless a flag set one
  if (po.visibility.fabric_albedo[0] < 0) po.visibility.fabric_albedo = render::DiffuseAlbedo(p);
  po.env_sun = opt.env_sun;
  po.env_sun_default = opt.env_sun_default;
  if (opt.yarn_table)  // the table's split sum for the environment (every table mode)
    po.yarn_ibl = [t = opt.yarn_table](const Vec3<double>& wo, yarn_table::IblLobe out[2]) {
      t->Ibl(wo, out);
    };
  if (opt.yarn_table && !(opt.yarn_table_ibl_only && opt.yarn_far_field)) {
    // the tabulated lobe for the lights too
    po.yarn_lobe = [t = opt.yarn_table](const Vec3<double>& wo, const Vec3<double>& wi,
                                        double out[2]) { t->Eval(wo, wi, out); };
  } else if (opt.yarn_far_field) {
    std::shared_ptr<const YarnFarField> ff = opt.yarn_far_field;
    if (opt.yarn_quadrature_nodes > 0) {
      auto lobe = std::make_shared<const yarn_lobe::Lobe>(ff->Description(opt.yarn_quadrature_nodes, 0));
      po.yarn_lobe = [lobe](const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) {
        lobe->Eval(wo, wi, out);
      };
    } else {
      po.yarn_lobe = [ff](const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) {
        ff->Eval(wo, wi, out);
      };
    }
  }
  if (opt.yarn_table && opt.yarn_ibl_bins && po.yarn_lobe) {  // one read per wi bin
    std::shared_ptr<const yarn_table::Table> t = opt.yarn_table;
    auto rows = std::make_shared<const std::vector<double>>(t->BinRoughness());
    po.yarn_ibl_taps = [t, rows](const Vec3<double>& wo, std::vector<yarn_table::IblTap>* taps) {
      t->BinTaps(wo, *rows, taps);
    };
  }
  return po;
}

// A copy of `full` restricted to the cache pixels `keep` (in that order).
std::unique_ptr<render::PreviewCache> Subset(const render::PreviewCache& full,
                                             const std::vector<int>& keep) {
  auto c = std::make_unique<render::PreviewCache>();
  c->width = full.width;
  c->height = full.height;
  c->options = full.options;
  c->features = full.features;
  c->dfg = full.dfg;
  c->sheen_albedo = full.sheen_albedo;
  c->woven_phase = full.woven_phase;
  const size_t K3 = size_t(full.options.roughness_nodes) * 3;
  const size_t KR = full.pixels.empty() ? K3 : full.radiance.size() / full.pixels.size();  // physical-aniso: K3 x bent nodes
  c->light_begin.push_back(0);
  for (int i : keep) {
    const size_t ui = size_t(i);
    c->pixels.push_back(full.pixels[ui]);
    c->NoV.push_back(full.NoV[ui]);
    for (int s = full.light_begin[ui]; s < full.light_begin[ui + 1]; ++s)
      c->light_samples.push_back(full.light_samples[size_t(s)]);
    c->light_begin.push_back(int(c->light_samples.size()));
    if (!full.tangent_v.empty()) {  // woven: per pixel t.v, b.v; per light sample 4 cosines
      c->tangent_v.insert(c->tangent_v.end(), full.tangent_v.begin() + long(ui * 2),
                          full.tangent_v.begin() + long(ui * 2 + 2));
      c->light_tangent.insert(c->light_tangent.end(),
                              full.light_tangent.begin() + long(full.light_begin[ui]) * 4,
                              full.light_tangent.begin() + long(full.light_begin[ui + 1]) * 4);
    }
    if (!full.yarn_ibl.empty())  // tabulated yarn lobes' split sum: 6 per pixel
      c->yarn_ibl.insert(c->yarn_ibl.end(), full.yarn_ibl.begin() + long(ui * 6),
                         full.yarn_ibl.begin() + long((ui + 1) * 6));
    if (!full.yarn_lobe.empty())  // far-field yarn lobe (measurement): 2 per light sample
      c->yarn_lobe.insert(c->yarn_lobe.end(),
                          full.yarn_lobe.begin() + long(full.light_begin[ui]) * 2,
                          full.yarn_lobe.begin() + long(full.light_begin[ui + 1]) * 2);
    if (!full.weave.empty()) {  // woven with weave maps: the sampled maps per pixel
      const size_t nc = size_t(render::WeaveMaps::kChannels);
      c->weave.insert(c->weave.end(), full.weave.begin() + long(ui * nc),
                      full.weave.begin() + long((ui + 1) * nc));
    }
    for (size_t k = 0; k < 3; ++k)
      if (!full.irradiance.empty()) c->irradiance.push_back(full.irradiance[ui * 3 + k]);
    for (size_t k = 0; k < 3; ++k)  // the light map's fabric bounce per unit albedo
      if (!full.irradiance_unit.empty()) c->irradiance_unit.push_back(full.irradiance_unit[ui * 3 + k]);
    for (size_t k = 0; k < 3; ++k)  // woven: the light map the yarn lobes reflect
      if (!full.light_map.empty()) c->light_map.push_back(full.light_map[ui * 3 + k]);
    for (size_t k = 0; k < 2; ++k)  // woven far-field: the lobes' albedos
      if (!full.yarn_albedo.empty()) c->yarn_albedo.push_back(full.yarn_albedo[ui * 2 + k]);
    if (!full.radiance.empty())
      c->radiance.insert(c->radiance.end(), full.radiance.begin() + long(ui * KR),
                         full.radiance.begin() + long((ui + 1) * KR));
    if (!full.yarn_radiance.empty()) {  // woven FIS (one K x 3 table) or bent (two: warp, weft)
      const size_t KY = full.yarn_radiance.size() / full.pixels.size();
      c->yarn_radiance.insert(c->yarn_radiance.end(), full.yarn_radiance.begin() + long(ui * KY),
                              full.yarn_radiance.begin() + long((ui + 1) * KY));
    }
    if (!full.geometry_roughness.empty())  // three.js IBL: geometryRoughness per pixel
      c->geometry_roughness.push_back(full.geometry_roughness[ui]);
    if (!full.sheen_radiance.empty())
      c->sheen_radiance.insert(c->sheen_radiance.end(), full.sheen_radiance.begin() + long(ui * K3),
                               full.sheen_radiance.begin() + long((ui + 1) * K3));
    if (!full.sheen_tilt_radiance.empty())  // s10-velvet sheen nap prototype
      c->sheen_tilt_radiance.insert(c->sheen_tilt_radiance.end(),
                                    full.sheen_tilt_radiance.begin() + long(ui * K3),
                                    full.sheen_tilt_radiance.begin() + long((ui + 1) * K3));
  }
  return c;
}

// Residuals (and the Jacobian) of one scene, with all of a model's parameter blocks.
template <int N>
class PreviewCost final : public ceres::CostFunction {
  using Jet = ceres::Jet<double, N>;

 public:
  // packed[b]: block b is a channel-separable colour (one derivative slot, see kJetWidths).
  PreviewCost(const SceneData& d, std::vector<int> block_sizes, std::vector<char> packed)
      : d_(d), sizes_(std::move(block_sizes)), packed_(std::move(packed)) {
    set_num_residuals(3 * d.blocks());
    for (int s : sizes_) mutable_parameter_block_sizes()->push_back(s);
    packed_.resize(sizes_.size(), 0);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    std::vector<double> x;
    for (size_t b = 0; b < sizes_.size(); ++b)
      for (int k = 0; k < sizes_[b]; ++k) x.push_back(parameters[b][k]);
    if (!jacobians) return Residuals<double>(x.data(), residuals, nullptr);
    // Dual indices only for the blocks Ceres wants a Jacobian of (the free ones; constant
    // blocks get jacobians[b] == nullptr), packed in order: at most N free scalars.
    std::vector<Jet> xj(x.size());
    std::vector<int> slot(sizes_.size(), -1);
    bool any_packed = false;
    {
      int next = 0;
      size_t k = 0;
      for (size_t b = 0; b < sizes_.size(); ++b) {
        const bool pack = jacobians[b] != nullptr && packed_[b] && sizes_[b] == 3;
        const int width = pack ? 1 : sizes_[b];
        const bool free_block = jacobians[b] != nullptr && next + width <= N;
        if (jacobians[b] != nullptr && !free_block) return false;  // FitImages checks this
        if (free_block) slot[b] = next;
        for (int j = 0; j < sizes_[b]; ++j, ++k)
          xj[k] = free_block ? Jet(x[k], next + (pack ? 0 : j)) : Jet(x[k]);
        if (free_block) next += width;
        any_packed = any_packed || pack;
      }
    }
    if (any_packed) return PackedResiduals(xj.data(), slot, residuals, jacobians);
    std::vector<Jet> r(static_cast<size_t>(num_residuals()));
    if (!Residuals<Jet>(xj.data(), residuals, r.data())) return false;
    for (size_t b = 0; b < sizes_.size(); ++b) {
      if (jacobians[b]) {
        for (int row = 0; row < num_residuals(); ++row)
          for (int k = 0; k < sizes_[b]; ++k)
            jacobians[b][row * sizes_[b] + k] = r[size_t(row)].v[slot[b] + k];
      }
    }
    return true;
  }

  // Residuals and Jacobians with packed colour slots: the block means carry packed
  // derivatives; each is expanded per parameter through the display transform's 3 x 3
  // Jacobian (a Jet<double, 3> evaluation at the mean).
  bool PackedResiduals(const Jet* x, const std::vector<int>& slot, double* residuals,
                       double** jacobians) const {
    using J3 = ceres::Jet<double, 3>;
    std::vector<Rgb<Jet>> px;
    render::EvaluatePreview(*d_.cache, x, px);
    bool finite = true;
    for (int b = 0; b < d_.blocks(); ++b) {
      Rgb<Jet> sum(Jet(0.0), Jet(0.0), Jet(0.0));
      const int begin = d_.block_begin[size_t(b)], end = d_.block_begin[size_t(b) + 1];
      for (int i = begin; i < end; ++i) sum += px[size_t(i)] * Jet(d_.pixel_weight[size_t(i)]);
      const Rgb<Jet> mean = sum * Jet(1.0 / d_.block_weight[size_t(b)]);
      const Rgb<J3> t = Transform(Rgb<J3>(J3(mean[0].a, 0), J3(mean[1].a, 1), J3(mean[2].a, 2)),
                                  d_.space, d_.op, d_.exposure);
      for (int c = 0; c < 3; ++c) {
        const size_t row = size_t(b) * 3 + size_t(c);
        const double w = d_.weight[size_t(b)][c];
        const double r = (t[c].a - d_.ref_t[size_t(b)][c]) * w;
        residuals[row] = r;
        finite = finite && std::isfinite(r) && ceres::isfinite(t[c]);
        for (size_t pb = 0; pb < sizes_.size(); ++pb) {
          if (!jacobians[pb]) continue;
          const int n = sizes_[pb];
          const bool pack = packed_[pb] && n == 3;
          for (int j = 0; j < n; ++j) {
            double dt = 0.0;  // d t_c / d x_{pb, j}
            if (pack) {
              dt = t[c].v[j] * mean[j].v[slot[pb]];
            } else {
              for (int k = 0; k < 3; ++k) dt += t[c].v[k] * mean[k].v[slot[pb] + j];
            }
            jacobians[pb][row * size_t(n) + size_t(j)] = w * dt;
            finite = finite && std::isfinite(w * dt);
          }
        }
      }
    }
    return finite;
  }

  template <typename T>
  bool Residuals(const T* x, double* residuals, T* out) const {
    std::vector<Rgb<T>> px;
    render::EvaluatePreview(*d_.cache, x, px);
    const int nb = d_.blocks();
    bool finite = true;
    for (int b = 0; b < nb; ++b) {
      Rgb<T> sum(Const<T>(0.0), Const<T>(0.0), Const<T>(0.0));
      const int begin = d_.block_begin[size_t(b)], end = d_.block_begin[size_t(b) + 1];
      for (int i = begin; i < end; ++i) sum += px[size_t(i)] * Const<T>(d_.pixel_weight[size_t(i)]);
      const Rgb<T> mean = sum * Const<T>(1.0 / d_.block_weight[size_t(b)]);
      const Rgb<T> t = Transform(mean, d_.space, d_.op, d_.exposure);
      for (int c = 0; c < 3; ++c) {
        const T r = (t[c] - Const<T>(d_.ref_t[size_t(b)][c])) * Const<T>(d_.weight[size_t(b)][c]);
        const size_t k = size_t(b) * 3 + size_t(c);
        if constexpr (std::is_same_v<T, double>) {
          residuals[k] = r;
          finite = finite && std::isfinite(r);
        } else {
          residuals[k] = r.a;
          out[k] = r;
          finite = finite && ceres::isfinite(r);
        }
      }
    }
    return finite;
  }

 private:
  const SceneData& d_;
  std::vector<int> sizes_;
  std::vector<char> packed_;
};

// Unweighted sum of squared block errors in the fit space for flat parameters x.
double SquaredError(const SceneData& d, const double* x) {
  std::vector<Rgb<double>> px;
  render::EvaluatePreview(*d.cache, x, px);
  double se = 0.0;
  for (int b = 0; b < d.blocks(); ++b) {
    const int b0 = d.block_begin[size_t(b)], b1 = d.block_begin[size_t(b) + 1];
    Rgb<double> sum(0, 0, 0);
    for (int i = b0; i < b1; ++i) sum += px[size_t(i)] * d.pixel_weight[size_t(i)];
    const Rgb<double> t = Transform(sum * (1.0 / d.block_weight[size_t(b)]), d.space, d.op, d.exposure);
    for (int c = 0; c < 3; ++c) se += std::pow(t[c] - d.ref_t[size_t(b)][c], 2);
  }
  return se;
}

double Mean3(const std::vector<float>& rgb, const std::vector<float>& mask) {
  double s = 0;
  size_t n = 0;
  for (size_t p = 0; p < mask.size(); ++p)
    if (mask[p] > 0.5f) {
      s += double(rgb[p * 3]) + double(rgb[p * 3 + 1]) + double(rgb[p * 3 + 2]);
      n += 3;
    }
  return n ? s / double(n) : 0.0;
}

using ParamTable = std::span<const ParamInfo>;
using SceneList = std::vector<std::unique_ptr<SceneData>>;
using ParamBlocks = std::vector<std::vector<double>>;

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

bool IsLocked(const FitOptions& opt, std::string_view name) {
  return std::find(opt.locked.begin(), opt.locked.end(), std::string(name)) != opt.locked.end();
}

// The index of the parameter block `name` in the table, or -1.
int BlockIndex(ParamTable table, std::string_view name) {
  int i = 0;
  for (const ParamInfo& p : table) {
    if (p.name == name) return i;
    ++i;
  }
  return -1;
}

// The Ceres parameter block sizes: one block per table entry.
std::vector<int> BlockSizes(ParamTable table) {
  std::vector<int> sizes;
  for (const ParamInfo& p : table) sizes.push_back(p.size);
  return sizes;
}

// Every --lock name must be a parameter of the model.
void CheckLockedNames(ParamTable table, const FitOptions& opt) {
  for (const std::string& name : opt.locked) {
    bool found = false;
    for (const ParamInfo& p : table) found = found || p.name == name;
    if (!found)
      throw FitError("--lock: model " + render::ToString(opt.start.model) + " has no parameter '" +
                     name + "'");
  }
}

// ---- per-scene setup: cache, blocks, transformed reference, weights ----

// The reference, the second reference and the scene card must all have the same size.
void CheckSceneSizes(const SceneInput& in) {
  const render::Scene& scene = *in.scene;
  const Reference& ref = *in.reference;
  if (in.second && (in.second->width != ref.width || in.second->height != ref.height))
    throw FitError(in.second->path + ": size differs from " + ref.path);
  if (ref.width != scene.card.width || ref.height != scene.card.height) {
    throw FitError(ref.path + ": reference is " + std::to_string(ref.width) + "x" +
                   std::to_string(ref.height) + " but " + in.scene_path + " renders " +
                   std::to_string(scene.card.width) + "x" + std::to_string(scene.card.height));
  }
}

// One B x B block of a scene at (bx, by), and what the block loop needs to judge it.
struct BlockGrid {
  const Reference& ref;
  const std::vector<int>& cache_index;  // image pixel -> cache pixel, -1 when not cached
  const std::vector<float>& fabric;     // preview fabric mask per image pixel (1 = fabric)
  int width = 0;                        // image width
  int B = 1;                            // block size
  int stride = 1;                       // pixel stride inside a block
};

// Coverage weight w of a reference pixel (docs/references.md): the reader's, or for
// references built in memory, 1 where fabric >= 0.999.
double PixelWeight(const Reference& ref, size_t p) {
  return ref.weight.empty() ? (ref.fabric[p] >= 0.999f ? 1.0 : 0.0) : double(ref.weight[p]);
}

// Why a block is not used.
enum class BlockVerdict { kKept, kNotPreviewFabric, kLowCoverage };

// Coverage-weighted sums over the block: sum(w x), sum(w^2 stderr^2) and sum(w). Not kept when
// some pixel is not fabric in the preview, or the coverage fraction sum(w) / B^2 is below
// min_coverage (uncovered pixels, e.g. gaps between yarns, are excluded from both sides).
BlockVerdict SumFabricBlock(const BlockGrid& g, int bx, int by, double min_coverage,
                            Rgb<double>& sum, Rgb<double>& var, double& wsum) {
  const int B = g.B, W = g.width;
  wsum = 0.0;
  for (int y = by; y < by + B; ++y)
    for (int x = bx; x < bx + B; ++x) {
      const size_t p = size_t(y) * size_t(W) + size_t(x);
      if (g.fabric[p] < 0.5f) return BlockVerdict::kNotPreviewFabric;
      const double w = PixelWeight(g.ref, p);
      wsum += w;
      for (int c = 0; c < 3; ++c) {
        sum[c] += w * double(g.ref.rgb[p * 3 + size_t(c)]);
        var[c] += std::pow(w * double(g.ref.std_error[p * 3 + size_t(c)]), 2);
      }
    }
  if (wsum <= 0.0 || wsum < min_coverage * double(B) * double(B)) return BlockVerdict::kLowCoverage;
  return BlockVerdict::kKept;
}

// Appends a block's transformed reference mean and its per-channel weights (see image_fit.h:
// the standard error through the transform, floored). n = sum of the coverage weights.
void AddBlockTarget(SceneData& d, const Rgb<double>& sum, const Rgb<double>& var, double n,
                    double floor_lin) {
  const Rgb<double> mean = sum * (1.0 / n);
  Rgb<double> se;
  for (int c = 0; c < 3; ++c) se[c] = std::sqrt(var[c]) / n;
  // Weights: sigma propagated through the transform by a one-sided difference.
  const Rgb<double> t = Transform(mean, d.space, d.op, d.exposure);
  const Rgb<double> tp = Transform(mean + se, d.space, d.op, d.exposure);
  Rgb<double> w;
  for (int c = 0; c < 3; ++c) {
    const double sigma = std::abs(tp[c] - t[c]);
    const double fl = d.space == Space::kLinear ? floor_lin : 0.01;
    w[c] = 1.0 / std::sqrt(sigma * sigma + fl * fl);
  }
  d.ref_t.push_back(t);
  d.weight.push_back(w);
}

// Transformed block mean of another image of the reference (the second reference or one of
// its halves: the noise floor), with the first reference's coverage weights (sum wsum).
Rgb<double> SecondBlockMean(const SceneData& d, const BlockGrid& g, const std::vector<float>& rgb,
                            int bx, int by, double wsum) {
  Rgb<double> s2(0, 0, 0);
  for (int y = by; y < by + g.B; ++y)
    for (int x = bx; x < bx + g.B; ++x) {
      const size_t p = size_t(y) * size_t(g.width) + size_t(x);
      for (int c = 0; c < 3; ++c)
        s2[c] += PixelWeight(g.ref, p) * double(rgb[p * 3 + size_t(c)]);
    }
  return Transform(s2 * (1.0 / wsum), d.space, d.op, d.exposure);
}

// Centre of each stride x stride cell (its first pixel would shift every block's sample mean
// by (stride - 1) / 2 pixels against the full-block reference mean), weighted by the
// reference coverage of its whole cell (the centre pixel alone would move the samples'
// weighted centroid when gaps line up with the stride); if no cell is covered, the samples
// weigh alike.
void KeepBlockSamples(const BlockGrid& g, int bx, int by, std::vector<int>& keep,
                      SceneData& d) {
  const size_t first = keep.size();
  double sampled = 0.0;
  for (int y0 = by; y0 < by + g.B; y0 += g.stride)
    for (int x0 = bx; x0 < bx + g.B; x0 += g.stride) {
      double cell = 0.0;
      for (int y = y0; y < std::min(y0 + g.stride, by + g.B); ++y)
        for (int x = x0; x < std::min(x0 + g.stride, bx + g.B); ++x)
          cell += PixelWeight(g.ref, size_t(y) * size_t(g.width) + size_t(x));
      const int cx = std::min(x0 + g.stride / 2, bx + g.B - 1);
      const int cy = std::min(y0 + g.stride / 2, by + g.B - 1);
      keep.push_back(g.cache_index[size_t(cy) * size_t(g.width) + size_t(cx)]);
      d.pixel_weight.push_back(cell);
      sampled += cell;
    }
  if (sampled <= 0.0) {
    for (size_t k = first; k < keep.size(); ++k) d.pixel_weight[k] = 1.0;
    sampled = double(keep.size() - first);
  }
  d.block_weight.push_back(sampled);
}

// The usable blocks of one scene (docs/references.md, "The coverage rule"), their targets and
// weights, and the cache pixels they sample (returned, in block order); counts the dropped.
std::vector<int> CollectBlocks(const SceneInput& in, const BlockGrid& g, int height,
                               double min_coverage, SceneData& d) {
  const Reference& ref = *in.reference;
  const double ref_mean = Mean3(ref.rgb, ref.fabric);
  const double floor_lin = 0.01 * std::max(ref_mean, 1e-6);
  const size_t values = size_t(ref.width) * size_t(ref.height) * 3;
  if (!in.second && (!ref.half_a.empty() || !ref.half_b.empty())) {
    if (ref.half_a.size() != values || ref.half_b.size() != values)
      throw FitError(ref.path + ": half images do not match the reference's size");
    try {
      d.half_scale = metrics::HalfDifferenceToFullStderr(ref.half_batches, ref.batches);
    } catch (const std::invalid_argument& e) {
      throw FitError(ref.path + ": " + e.what());
    }
  }
  std::vector<int> keep;
  d.block_begin.push_back(0);
  const int B = g.B, W = g.width, H = height;
  for (int by = 0; by + B <= H; by += B) {
    for (int bx = 0; bx + B <= W; bx += B) {
      Rgb<double> sum(0, 0, 0), var(0, 0, 0);
      double wsum = 0.0;
      const BlockVerdict v = SumFabricBlock(g, bx, by, min_coverage, sum, var, wsum);
      if (v == BlockVerdict::kNotPreviewFabric) ++d.dropped_preview;
      if (v == BlockVerdict::kLowCoverage) ++d.dropped_coverage;
      if (v != BlockVerdict::kKept) continue;
      AddBlockTarget(d, sum, var, wsum, floor_lin);
      if (in.second) {
        d.second_t.push_back(SecondBlockMean(d, g, in.second->rgb, bx, by, wsum));
      } else if (!ref.half_a.empty()) {
        d.half_a_t.push_back(SecondBlockMean(d, g, ref.half_a, bx, by, wsum));
        d.half_b_t.push_back(SecondBlockMean(d, g, ref.half_b, bx, by, wsum));
      }
      KeepBlockSamples(g, bx, by, keep, d);
      d.block_begin.push_back(int(keep.size()));
    }
  }
  return keep;
}

// The pixels KeepBlockSamples can pick (the stride cells' centres of every whole block).
std::vector<unsigned char> SampleMask(int width, int height, int B, int stride) {
  std::vector<unsigned char> mask(size_t(width) * size_t(height), 0);
  for (int by = 0; by + B <= height; by += B)
    for (int bx = 0; bx + B <= width; bx += B)
      for (int y0 = by; y0 < by + B; y0 += stride)
        for (int x0 = bx; x0 < bx + B; x0 += stride) {
          const int cx = std::min(x0 + stride / 2, bx + B - 1);
          const int cy = std::min(y0 + stride / 2, by + B - 1);
          mask[size_t(cy) * size_t(width) + size_t(cx)] = 1;
        }
  return mask;
}

// One scene's fit data: its preview cache restricted to the sampled pixels of its blocks.
std::unique_ptr<SceneData> BuildSceneData(const SceneInput& in, const FitOptions& opt, int B,
                                          int stride) {
  CheckSceneSizes(in);
  const render::Scene& scene = *in.scene;
  const Reference& ref = *in.reference;
  auto d = std::make_unique<SceneData>();
  d->scene_path = in.scene_path;
  d->reference_path = ref.path;
  d->space = opt.space;
  d->op = render::ParseToneMapping(scene.card.tone_mapping);
  d->exposure = scene.card.exposure;
  render::PreviewOptions po = PreviewOptionsFor(opt, opt.start);
  // Only the pixels a block can sample get preview cache entries (fit speed: the radiance
  // tables of the other pixels were built and thrown away); every pixel's fabric flag is kept.
  po.sample_mask = SampleMask(scene.card.width, scene.card.height, B, stride);
  po.weave_footprint_scale = stride;  // a kept pixel stands for its stride x stride cell
  const auto full = render::PreviewCache::Build(scene, in.environment, po);
  std::vector<int> cache_index(size_t(full->width) * size_t(full->height), -1);
  for (size_t i = 0; i < full->pixels.size(); ++i) cache_index[size_t(full->pixels[i])] = int(i);
  const BlockGrid grid{ref, cache_index, full->fabric_mask, scene.card.width, B, stride};
  const std::vector<int> keep = CollectBlocks(in, grid, scene.card.height, opt.min_coverage, *d);
  if (d->blocks() == 0) {
    throw FitError(in.scene_path + " / " + ref.path + ": no " + std::to_string(B) + "x" +
                   std::to_string(B) + " block is usable (" + std::to_string(d->dropped_preview) +
                   " not all fabric in the preview: --level too large, or the wrong scene; " +
                   std::to_string(d->dropped_coverage) + " with reference coverage below " +
                   std::to_string(opt.min_coverage) +
                   ": check --alpha / --coverage-channel, or lower --min-coverage)");
  }
  d->cache = Subset(*full, keep);
  return d;
}

SceneList BuildScenes(const std::vector<SceneInput>& inputs, const FitOptions& opt) {
  const int B = 1 << std::max(0, opt.level);
  const int stride = opt.pixel_stride > 0 ? opt.pixel_stride : std::max(1, B / 4);
  SceneList data;
  for (const SceneInput& in : inputs) data.push_back(BuildSceneData(in, opt, B, stride));
  return data;
}

// ---- one start of the multi-start ----

// Mean reference colour (linear) of a reference's fabric pixels, to start the base colour.
Rgb<double> StartColour(const Reference& r) {
  Rgb<double> ref_colour(0.5, 0.5, 0.5);
  double s[3] = {0, 0, 0};
  double n = 0;
  for (size_t p = 0; p < r.fabric.size(); ++p)
    if (r.weight.empty() ? r.fabric[p] > 0.999f : r.weight[p] > 0.5f) {
      for (int c = 0; c < 3; ++c) s[c] += double(r.rgb[p * 3 + size_t(c)]);
      n += 1;
    }
  if (n > 0) {
    const double mx = std::max({s[0], s[1], s[2]}) / n;
    for (int c = 0; c < 3; ++c)
      ref_colour[c] = std::clamp(s[c] / n / std::max(mx, 1e-6) * 0.6, 0.02, 0.95);
  }
  return ref_colour;
}

// Parameter blocks, initialised from the start preset; unlocked colours from the reference.
ParamBlocks StartBlocks(ParamTable table, const FitOptions& opt, double r0,
                        const Rgb<double>& ref_colour) {
  ParamBlocks blocks;
  int off = 0;
  for (const ParamInfo& p : table) {
    std::vector<double> v(size_t(p.size));
    for (int c = 0; c < p.size; ++c) v[size_t(c)] = opt.start.values[size_t(off + c)];
    if (!IsLocked(opt, p.name) && opt.init_from_reference) {
      if (p.name == "roughness" || p.name == "sheen_roughness") v[0] = r0;
      if (p.name == "base_color")
        for (int c = 0; c < 3; ++c) v[size_t(c)] = ref_colour[c];
      if (p.name == "sheen_color")
        for (int c = 0; c < 3; ++c) v[size_t(c)] = 0.5;
      if (p.name == "subsurface_color")
        for (int c = 0; c < 3; ++c) v[size_t(c)] = 0.2;
    }
    blocks.push_back(v);
    off += p.size;
  }
  return blocks;
}

// Whether a parameter block is held constant: locked, or ignored by the model's options
// (cloth: sheen colour unless explicit, subsurface colour without --subsurface).
bool IsConstantBlock(const ParamInfo& p, const FitOptions& opt) {
  const bool ignored = opt.start.model == render::ModelKind::kCloth &&
                       ((p.name == "sheen_color" &&
                         opt.start.cloth.sheen_default != cloth::SheenDefault::kExplicit) ||
                        (p.name == "subsurface_color" && !opt.start.cloth.subsurface));
  return ignored || IsLocked(opt, p.name);
}

// Free scalars of a model under the options.
int FreeScalars(ParamTable table, const FitOptions& opt) {
  int n = 0;
  for (const ParamInfo& p : table)
    if (!IsConstantBlock(p, opt)) n += p.size;
  return n;
}

// Whether a parameter's RGB channels enter only the same preview channel (the colour packing
// of kJetWidths). `yarn`: the woven yarn layering of the preview caches.
bool ChannelSeparable(const ParamInfo& p, const FitOptions& opt, woven::YarnLayer yarn) {
  if (!opt.pack_colours || p.size != 3) return false;
  const std::string_view name = p.name;
  if (name == "base_color") return true;  // every model: diffuse and F0 per channel
  switch (opt.start.model) {
    case render::ModelKind::kCloth: return name == "sheen_color" || name == "subsurface_color";
    case render::ModelKind::kWoven:
      return name == "specular_color" && yarn == woven::YarnLayer::kAdditive;
    default: return false;  // physical-sheen, gltf-sheen: sheen albedo scaling uses max3
  }
}

std::vector<char> PackedBlocks(ParamTable table, const FitOptions& opt, woven::YarnLayer yarn) {
  std::vector<char> packed;
  for (const ParamInfo& p : table) packed.push_back(ChannelSeparable(p, opt, yarn) ? 1 : 0);
  return packed;
}

// Derivative slots the Jet must carry: the free scalars, a packed colour counting once.
int FreeSlots(ParamTable table, const FitOptions& opt, woven::YarnLayer yarn) {
  int n = 0;
  for (const ParamInfo& p : table)
    if (!IsConstantBlock(p, opt)) n += ChannelSeparable(p, opt, yarn) ? 1 : p.size;
  return n;
}

// The narrowest instantiated Jet width holding `free_scalars` (0 when none does).
int JetWidthFor(int free_scalars) {
  for (int w : kJetWidths)
    if (free_scalars <= w) return w;
  return 0;
}

ceres::CostFunction* MakePreviewCost(const SceneData& d, const std::vector<int>& sizes,
                                     const std::vector<char>& packed, int jet_width) {
  switch (jet_width) {
    case 4: return new PreviewCost<4>(d, sizes, packed);
    case 6: return new PreviewCost<6>(d, sizes, packed);
    case 8: return new PreviewCost<8>(d, sizes, packed);
    default: return new PreviewCost<kMaxJetWidth>(d, sizes, packed);
  }
}

woven::YarnLayer YarnLayerOf(const SceneList& data) {
  return data.empty() ? woven::YarnLayer::kAdditive : data[0]->cache->options.woven.yarn_layer;
}

// One residual block per scene, with the chosen robust loss.
void AddSceneResiduals(ceres::Problem& problem, const SceneList& data, ParamTable table,
                       const std::vector<int>& sizes, const FitOptions& opt,
                       const std::vector<double*>& ptrs) {
  const woven::YarnLayer yarn = YarnLayerOf(data);
  const std::vector<char> packed = PackedBlocks(table, opt, yarn);
  const int jet_width = JetWidthFor(FreeSlots(table, opt, yarn));
  for (const auto& d : data) {
    ceres::LossFunction* loss = nullptr;
    if (opt.loss == Loss::kHuber) loss = new ceres::HuberLoss(opt.loss_scale);
    if (opt.loss == Loss::kCauchy) loss = new ceres::CauchyLoss(opt.loss_scale);
    problem.AddResidualBlock(MakePreviewCost(*d, sizes, packed, jet_width), loss, ptrs);
  }
}

// Locked and ignored blocks are constant; the others get the table's bounds (cloth roughness:
// the variant's minimum). Throws when a start value lies outside its bounds.
void SetBoundsOrConstant(ceres::Problem& problem, ParamTable table, const FitOptions& opt,
                         const ParamBlocks& blocks, const std::vector<double*>& ptrs) {
  const render::ModelKind model = opt.start.model;
  size_t bi = 0;
  for (const ParamInfo& p : table) {
    double lower = p.lower;
    if (model == render::ModelKind::kCloth && p.name == "roughness")
      lower = cloth::MinRoughness(opt.start.cloth);
    if (IsConstantBlock(p, opt)) {
      problem.SetParameterBlockConstant(ptrs[bi]);
    } else {
      for (int c = 0; c < p.size; ++c) {
        if (blocks[bi][size_t(c)] < lower || blocks[bi][size_t(c)] > p.upper) {
          throw FitError("fit: start value of " + std::string(p.name) + " (" +
                         std::to_string(blocks[bi][size_t(c)]) + ") is outside [" +
                         std::to_string(lower) + ", " + std::to_string(p.upper) + "]");
        }
        problem.SetParameterLowerBound(ptrs[bi], c, lower);
        problem.SetParameterUpperBound(ptrs[bi], c, p.upper);
      }
    }
    ++bi;
  }
}

// Solves one start in place (blocks hold the start on entry, the solution on return).
ceres::Solver::Summary SolveStart(const SceneList& data, ParamTable table,
                                  const std::vector<int>& sizes, const FitOptions& opt,
                                  ParamBlocks& blocks) {
  ceres::Problem problem;
  std::vector<double*> ptrs;
  for (auto& b : blocks) ptrs.push_back(b.data());
  AddSceneResiduals(problem, data, table, sizes, opt, ptrs);
  SetBoundsOrConstant(problem, table, opt, blocks, ptrs);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = opt.max_iterations;
  so.function_tolerance = opt.function_tolerance;
  so.minimizer_progress_to_stdout = opt.verbose;
  so.num_threads = 1;  // the residual evaluation is parallel inside (TBB)
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  return summary;
}

bool AllFinite(const ParamBlocks& blocks) {
  bool finite = true;
  for (auto& b : blocks)
    for (double v : b) finite = finite && std::isfinite(v);
  return finite;
}

std::vector<double> Flatten(const ParamBlocks& blocks) {
  std::vector<double> flat;
  for (auto& b : blocks) flat.insert(flat.end(), b.begin(), b.end());
  return flat;
}

// Unweighted RMSE over the blocks of all scenes, in the fit space, at flat parameters x.
double RmseOverScenes(const SceneList& data, const double* x) {
  double se = 0.0;
  int count = 0;
  for (const auto& d : data) {
    se += SquaredError(*d, x);
    count += 3 * d->blocks();
  }
  return std::sqrt(se / std::max(count, 1));
}

// Makes `best` the result of this start (keeping the start and iteration counts).
void TakeStart(FitResult& best, const ceres::Solver::Summary& summary, const FitOptions& opt,
               const ParamBlocks& blocks) {
  const int starts = best.starts, iterations = best.iterations;
  best = FitResult{};
  best.starts = starts;
  best.iterations = iterations;
  best.usable = true;
  best.final_cost = summary.final_cost;
  best.initial_cost = summary.initial_cost;
  best.termination = ceres::TerminationTypeToString(summary.termination_type);
  best.converged = summary.termination_type == ceres::CONVERGENCE;
  best.solver_report = summary.BriefReport();
  best.preset = opt.start;
  best.preset.values.clear();
  for (auto& b : blocks) best.preset.values.insert(best.preset.values.end(), b.begin(), b.end());
}

// Unweighted per-scene errors in the fit space at the fitted parameters, and their total.
void AddSceneErrors(const SceneList& data, FitResult& best) {
  double total_se = 0.0;
  int total_n = 0;
  for (const auto& d : data) {
    const double se = SquaredError(*d, best.preset.values.data());
    SceneError e;
    e.scene = d->scene_path;
    e.reference = d->reference_path;
    e.blocks = d->blocks();
    e.dropped_preview = d->dropped_preview;
    e.dropped_coverage = d->dropped_coverage;
    e.rmse = std::sqrt(se / (3.0 * d->blocks()));
    if (!d->second_t.empty()) {
      double s2 = 0.0;
      for (size_t b = 0; b < d->second_t.size(); ++b)
        for (int c = 0; c < 3; ++c) s2 += std::pow(d->second_t[b][c] - d->ref_t[b][c], 2);
      e.noise_floor = std::sqrt(s2 / (3.0 * double(d->second_t.size()))) / std::sqrt(2.0);
      e.noise_floor_source = "second reference";
    } else if (!d->half_a_t.empty()) {
      // E|A - B|^2 = sigma_full^2 x K^2 / (kA (K - kA)) per block and channel (linear; first
      // order through the display transform): fit/metrics/reference_halves.h.
      double s2 = 0.0;
      for (size_t b = 0; b < d->half_a_t.size(); ++b)
        for (int c = 0; c < 3; ++c) s2 += std::pow(d->half_a_t[b][c] - d->half_b_t[b][c], 2);
      e.noise_floor = std::sqrt(s2 / (3.0 * double(d->half_a_t.size()))) * d->half_scale;
      e.noise_floor_source = "reference halves";
    }
    best.scenes.push_back(e);
    total_se += se;
    total_n += 3 * d->blocks();
    best.residuals += 3 * d->blocks();
  }
  best.rmse = std::sqrt(total_se / std::max(total_n, 1));
}

}  // namespace

std::string ToString(Space s) {
  switch (s) {
    case Space::kDisplay: return "display";
    case Space::kLinear: return "linear";
    case Space::kLog: return "log";
  }
  return "?";
}

Space ParseSpace(const std::string& s) {
  if (s == "display") return Space::kDisplay;
  if (s == "linear") return Space::kLinear;
  if (s == "log") return Space::kLog;
  throw std::invalid_argument("unknown space '" + s + "' (valid: display, linear, log)");
}

Reference ReadReference(const std::string& path) { return ReadReference(path, ReferenceOptions{}); }

int AutoLevel(const render::Scene& scene, double weave_period_uv, int max_level) {
  render::EmbreeScene bvh(scene);
  std::vector<double> footprints;
  const int W = scene.card.width, H = scene.card.height;
  for (int y = 0; y + 1 < H; y += 4) {
    for (int x = 0; x + 1 < W; x += 4) {
      std::array<double, 2> uv[3];
      bool ok = true;
      const double d[3][2] = {{0.5, 0.5}, {1.5, 0.5}, {0.5, 1.5}};
      for (int k = 0; k < 3 && ok; ++k) {
        std::array<double, 3> org, dir;
        scene.CameraRay(x + d[k][0], y + d[k][1], org, dir);
        const render::Hit h = bvh.Intersect(org, dir);
        ok = h.valid && scene.meshes[size_t(h.mesh)].is_fabric;
        if (ok) uv[k] = bvh.Attributes(h).uv;
      }
      if (!ok) continue;
      const double fx = std::hypot(uv[1][0] - uv[0][0], uv[1][1] - uv[0][1]);
      const double fy = std::hypot(uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]);
      footprints.push_back(std::max(fx, fy));
    }
  }
  if (footprints.empty() || weave_period_uv <= 0.0) return 1;
  std::nth_element(footprints.begin(), footprints.begin() + long(footprints.size() / 2),
                   footprints.end());
  const double footprint = footprints[footprints.size() / 2];  // uv per pixel
  const double pixels_per_period = weave_period_uv / std::max(footprint, 1e-12);
  int level = 1;
  while (level < max_level && double(1 << level) < 2.0 * pixels_per_period) ++level;
  return level;
}

int AutoLevel(const std::vector<SceneInput>& inputs, double weave_period_uv, int max_level) {
  if (weave_period_uv <= 0.0 || inputs.empty()) return 2;
  int level = 1;
  for (const SceneInput& in : inputs)
    level = std::max(level, AutoLevel(*in.scene, weave_period_uv, max_level));
  return level;
}

std::vector<float> RenderPreviewFrame(const render::Scene& scene, const render::Environment* env,
                                      const render::MaterialPreset& preset,
                                      render::IblEngine engine,
                                      std::optional<render::SunMode> env_sun,
                                      render::SunMode env_sun_default) {
  render::PreviewOptions o;
  o.env_sun = env_sun;
  o.env_sun_default = env_sun_default;
  o.model = preset.model;
  o.cloth = preset.cloth;
  o.woven = render::PreviewWovenOptions(preset);
  render::ApplyPresetYarnLobe(preset, &o);  // "woven": {"yarn_lobe"}
  o.ibl_engine = engine;
  o.weave_maps = render::LoadPresetWeaveMaps(preset);  // woven weave maps (null: none)
  auto cache = render::PreviewCache::Build(scene, env, o);
  std::vector<Rgb<double>> px;
  render::EvaluatePreview(*cache, preset.values.data(), px);
  return render::ComposeFrame(*cache, px);
}

std::vector<float> RenderPreviewFrame(const render::Scene& scene, const render::Environment* env,
                                      const render::MaterialPreset& preset,
                                      const FitOptions& fit) {
  const render::PreviewOptions o = PreviewOptionsFor(fit, preset);
  auto cache = render::PreviewCache::Build(scene, env, o);
  std::vector<Rgb<double>> px;
  render::EvaluatePreview(*cache, preset.values.data(), px);
  return render::ComposeFrame(*cache, px);
}

struct PreparedScenes {
  SceneList data;
  int level = 0, stride = 0;
  Space space = Space::kDisplay;
  double min_coverage = 0.0;
  render::ModelKind model = render::ModelKind::kCloth;
  nlohmann::json weave_maps;  // the start preset's "weave_maps" field (null: none)
  int exact_ibl_samples = 0, exact_irradiance_samples = 0;
  unsigned exact_ibl_seed = 1;
  double sheen_tilt_degrees = 0.0;
  bool shadows = false;
  render::VisibilityOptions visibility;
  render::IblEngine ibl_engine = render::IblEngine::kFilament;
  woven::IblMode woven_ibl = woven::IblMode::kSplit;
  std::optional<render::SunMode> env_sun;
  render::SunMode env_sun_default = render::SunMode::kOff;
  int fis_taps = 0, fis_diffuse_taps = 0;
  std::shared_ptr<const YarnFarField> yarn_far_field;
  std::shared_ptr<const yarn_table::Table> yarn_table;
  bool yarn_table_ibl_only = false;
  int yarn_quadrature_nodes = 0;
  bool yarn_ibl_bins = false;
  std::shared_ptr<const yarn_lobe::FarField> yarn_lobe;  // the start preset's (the lobe is not fitted)
  double seconds = 0.0;
};

namespace {
bool SameVisibility(const render::VisibilityOptions& a, const render::VisibilityOptions& b) {
  return a.ao == b.ao && a.weighting == b.weighting && a.indirect == b.indirect &&
         a.samples == b.samples &&
         a.hit_samples == b.hit_samples && a.bounces == b.bounces &&
         a.max_distance == b.max_distance && a.seed == b.seed &&
         a.fabric_albedo == b.fabric_albedo;
}
nlohmann::json WeaveMapsField(const render::MaterialPreset& p) {
  const auto it = p.extra.find("weave_maps");
  return it == p.extra.end() ? nlohmann::json() : *it;
}

// Whether woven's yarn lobes at `p` are one isotropic GGX lobe (ParametersWithoutEffect).
bool IsotropicGgxYarnLobes(const render::MaterialPreset& p, const FitOptions& opt) {
  if (p.model != render::ModelKind::kWoven || p.yarn_lobe || opt.yarn_far_field ||
      opt.yarn_table || p.woven.ibl == woven::IblMode::kBent)
    return false;
  const int s = p.Offset("anisotropy");
  return size_t(s) < p.values.size() && std::abs(p.values[size_t(s)]) <= kIsotropicAnisotropy;
}
}  // namespace

int FreeParameterCount(const FitOptions& options) {
  return FreeScalars(render::ParameterTable(options.start.model), options);
}

std::vector<std::string> ParametersWithoutEffect(const render::MaterialPreset& p,
                                                 const FitOptions& opt, std::string* reason) {
  std::vector<std::string> names;
  if (!IsotropicGgxYarnLobes(p, opt)) return names;
  // the two lobes' weights: the weave maps' per-texel warp / weft ratios, the tints
  const Rgb<double>& tw = p.woven.tint_warp;
  const Rgb<double>& tf = p.woven.tint_weft;
  const bool same_weights =
      WeaveMapsField(p).is_null() && tw.r == tf.r && tw.g == tf.g && tw.b == tf.b;
  if (same_weights && !IsLocked(opt, "warp_share")) names.push_back("warp_share");
  if (!IsLocked(opt, "twist")) names.push_back("twist");
  if (reason && !names.empty()) *reason = "at anisotropy 0";
  return names;
}

void ApplyNoEffect(const FitOptions& opt, FitResult* r) {
  const std::vector<std::string> none = ParametersWithoutEffect(r->preset, opt, nullptr);
  const bool isotropic = IsotropicGgxYarnLobes(r->preset, opt);
  for (AtBound& b : r->at_bound)
    if (std::find(none.begin(), none.end(), b.name) != none.end() ||
        (isotropic && b.name == "anisotropy" && !b.upper))
      b.flagged = false;
}

namespace {
std::shared_ptr<PreparedScenes> BuildPrepared(const std::vector<SceneInput>& inputs,
                                              const FitOptions& opt);
}  // namespace

std::shared_ptr<const PreparedScenes> PrepareScenes(const std::vector<SceneInput>& inputs,
                                                    const FitOptions& opt) {
  return BuildPrepared(inputs, opt);
}

namespace {
std::shared_ptr<PreparedScenes> BuildPrepared(const std::vector<SceneInput>& inputs,
                                              const FitOptions& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  if (inputs.empty()) throw FitError("fit: no (scene, reference) pairs");
  auto p = std::make_shared<PreparedScenes>();
  p->data = BuildScenes(inputs, opt);
  p->level = opt.level;
  p->stride = opt.pixel_stride;
  p->space = opt.space;
  p->min_coverage = opt.min_coverage;
  p->model = opt.start.model;
  p->weave_maps = WeaveMapsField(opt.start);
  p->exact_ibl_samples = opt.exact_ibl_samples;
  p->exact_ibl_seed = opt.exact_ibl_seed;
  p->exact_irradiance_samples = opt.exact_irradiance_samples;
  p->sheen_tilt_degrees = opt.sheen_tilt_degrees;
  p->shadows = opt.shadows;
  p->visibility = opt.visibility;
  p->ibl_engine = opt.ibl_engine;
  p->env_sun = opt.env_sun;
  p->env_sun_default = opt.env_sun_default;
  p->woven_ibl = opt.start.woven.ibl;
  p->fis_taps = opt.start.woven.fis_taps;
  p->fis_diffuse_taps = opt.start.woven.fis_diffuse_taps;
  p->yarn_far_field = opt.yarn_far_field;
  p->yarn_table = opt.yarn_table;
  p->yarn_table_ibl_only = opt.yarn_table_ibl_only;
  p->yarn_quadrature_nodes = opt.yarn_quadrature_nodes;
  p->yarn_ibl_bins = opt.yarn_ibl_bins;
  p->yarn_lobe = opt.start.yarn_lobe;
  p->seconds = SecondsSince(t0);
  return p;
}
}  // namespace

double PreparedSeconds(const PreparedScenes& prepared) { return prepared.seconds; }

FitResult FitImages(const std::vector<SceneInput>& inputs, const FitOptions& opt) {
  return FitImages(inputs, opt, nullptr);
}

namespace {
FitResult FitImagesOnce(const std::vector<SceneInput>& inputs, const FitOptions& opt,
                        const PreparedScenes* prepared);

// The second pass's scenes from the first's, in place: every cache with a one-bounce light map
// gets irradiance += (kd' - kd) x irradiance_unit (exact: the bounce is linear in the fabric's
// albedo, render/preview/visibility.h). False when some light map cannot be re-weighted (more
// bounces): the caller rebuilds.
bool ReweightLightMaps(PreparedScenes* p, const std::array<double, 3>& kd_new) {
  for (const auto& d : p->data) {
    const render::PreviewCache& c = *d->cache;
    if (c.options.visibility.indirect && c.irradiance_unit.size() != c.irradiance.size())
      return false;
    if (!c.light_map.empty() && c.light_map.size() != c.irradiance_unit.size()) return false;
    const std::array<double, 3>& kd = c.options.visibility.fabric_albedo;
    if (!c.irradiance_unit.empty() && (kd[0] < 0 || kd[1] < 0 || kd[2] < 0))
      return false;  // the glTF's colour: not known here (checked before anything changes)
  }
  for (auto& d : p->data) {
    render::PreviewCache& c = *d->cache;
    if (c.irradiance_unit.empty()) continue;
    const std::array<double, 3> kd = c.options.visibility.fabric_albedo;
    for (size_t i = 0; i < c.irradiance.size(); ++i)
      c.irradiance[i] = float(double(c.irradiance[i]) +
                              (kd_new[i % 3] - kd[i % 3]) * double(c.irradiance_unit[i]));
    // the light map alone (woven's yarn lobes reflect it): the same bounce, the same re-weighting
    for (size_t i = 0; i < c.light_map.size(); ++i)
      c.light_map[i] = float(double(c.light_map[i]) +
                             (kd_new[i % 3] - kd[i % 3]) * double(c.irradiance_unit[i]));
    c.options.visibility.fabric_albedo = kd_new;
  }
  p->visibility.fabric_albedo = kd_new;
  return true;
}

// Whether some scene bakes a light map whose fabric bounce takes the fitted albedo (a card's
// light map or --indirect, without an explicit fabric albedo): FitOptions::card_visibility.
bool NeedsAlbedoPass(const std::vector<SceneInput>& inputs, const FitOptions& opt) {
  if (opt.visibility.fabric_albedo[0] >= 0 || opt.exact_ibl_samples > 0) return false;
  if (opt.visibility.indirect) return true;
  if (!opt.card_visibility || opt.visibility.enabled()) return false;
  for (const SceneInput& in : inputs)
    if (in.scene && in.scene->card.visibility && in.scene->card.visibility->light_map) return true;
  return false;
}
}  // namespace

FitResult FitImages(const std::vector<SceneInput>& inputs, const FitOptions& opt,
                    const PreparedScenes* prepared) {
  return FitImagesOnce(inputs, opt, prepared);
}

FitResult FitWithLightMapAlbedo(
    const std::vector<SceneInput>& inputs, const FitOptions& opt,
    const std::function<FitResult(const FitOptions&, const PreparedScenes*)>& fit) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!NeedsAlbedoPass(inputs, opt)) return fit(opt, nullptr);
  // cloth's caches depend on its options and are never shared (FitImages refuses them)
  std::shared_ptr<PreparedScenes> own;
  if (opt.start.model != render::ModelKind::kCloth) own = BuildPrepared(inputs, opt);
  FitResult first = fit(opt, own.get());
  if (own) {  // the preparation was done here
    first.setup_seconds += own->seconds;
    first.seconds += own->seconds;
  }
  if (!first.usable) return first;
  // Second pass: the light map baked with the fitted diffuse albedo, one start at the solution.
  FitOptions o2 = opt;
  o2.visibility.fabric_albedo = render::DiffuseAlbedo(first.preset);
  if (o2.visibility.fabric_albedo[0] < 0) return first;  // no base colour to bounce
  o2.start = first.preset;
  o2.init_from_reference = false;
  o2.start_roughness = {0.0};
  const bool reweighted = own && ReweightLightMaps(own.get(), o2.visibility.fabric_albedo);
  FitResult second = fit(o2, reweighted ? own.get() : nullptr);
  if (!second.usable) return first;
  // The record keeps both passes' paths (fit.woven_paths): the first pass's under
  // "first pass: ", the second's under "albedo pass: " (session 15; before, the first pass's
  // cloth-basin paths vanished from the preset).
  std::vector<FitResult::Candidate> both;
  for (FitResult::Candidate c : first.candidates) {
    c.name = "first pass: " + c.name;
    both.push_back(std::move(c));
  }
  for (FitResult::Candidate c : second.candidates) {
    c.name = "albedo pass: " + c.name;
    both.push_back(std::move(c));
  }
  second.candidates = std::move(both);
  second.starts += first.starts;
  second.iterations += first.iterations;
  second.setup_seconds += first.setup_seconds;
  second.albedo_pass = true;
  // The record's errors are those of the preset as it is drawn (session 21): its light map
  // bounces the preset's own albedo, as evaluate, render-preview and web/ bake it, not the
  // first pass's that the second pass fitted with. One locked pass at the solution (no
  // iteration; re-weighted in place when the light maps allow). Before, fit.rmse and evaluate
  // differed in the 5th digit wherever a strong light bounced (the studio's panels, docs/sun.md).
  const std::array<double, 3> kd_final = render::DiffuseAlbedo(second.preset);
  if (kd_final[0] >= 0 && kd_final != o2.visibility.fabric_albedo) {
    FitOptions o3 = o2;
    o3.visibility.fabric_albedo = kd_final;
    o3.start = second.preset;
    o3.locked.clear();
    for (const auto& p : render::ParameterTable(o3.start.model)) o3.locked.emplace_back(p.name);
    o3.start_roughness = {0.0};
    const bool rw = reweighted && ReweightLightMaps(own.get(), kd_final);
    const FitResult at = FitImages(inputs, o3, rw ? own.get() : nullptr);
    if (at.usable) {
      second.rmse = at.rmse;
      second.scenes = at.scenes;
      second.final_cost = at.final_cost;  // the objective at the solution, same light map
      if (!rw) second.setup_seconds += at.setup_seconds;  // a rebuild (no in-place re-weight)
    }  // else (the same inputs just fitted; not seen): the albedo pass's errors stay
  }
  second.seconds = SecondsSince(t0);
  return second;
}

namespace {
FitResult FitImagesOnce(const std::vector<SceneInput>& inputs, const FitOptions& opt,
                        const PreparedScenes* prepared) {
  const auto t0 = std::chrono::steady_clock::now();
  if (inputs.empty()) throw FitError("fit: no (scene, reference) pairs");
  const render::ModelKind model = opt.start.model;
  const auto table = render::ParameterTable(model);
  const std::vector<int> sizes = BlockSizes(table);
  CheckLockedNames(table, opt);
  {  // the start's flat vector must hold the model's table (the preview reads it by offset)
    size_t n = 0;
    for (const ParamInfo& info : table) n += size_t(info.size);
    if (opt.start.values.size() != n)
      throw FitError("fit: the start preset of model " + render::ToString(model) + " has " +
                     std::to_string(opt.start.values.size()) + " values; its parameter table " +
                     "has " + std::to_string(n));
  }
  // The Jacobian carries at most kMaxJetWidth = 10 free scalars (ceres::Jet<double, 10>).
  const int free_scalars = FreeScalars(table, opt);
  if (JetWidthFor(free_scalars) == 0)
    throw FitError("fit: model " + render::ToString(model) + " has " + std::to_string(free_scalars) +
                   " free parameters; at most 10 (lock some with --lock)");

  // Per scene: cache, blocks, transformed reference, weights (built here, or prepared by the
  // caller for the same inputs and cache-relevant options: checked).
  std::shared_ptr<const PreparedScenes> own;
  if (prepared) {
    if (prepared->data.size() != inputs.size() || prepared->level != opt.level ||
        prepared->stride != opt.pixel_stride || prepared->space != opt.space ||
        prepared->min_coverage != opt.min_coverage || prepared->model != opt.start.model ||
        (opt.start.model == render::ModelKind::kCloth) ||
        prepared->weave_maps != WeaveMapsField(opt.start) ||
        prepared->exact_ibl_samples != opt.exact_ibl_samples ||
        prepared->exact_ibl_seed != opt.exact_ibl_seed ||
        prepared->exact_irradiance_samples != opt.exact_irradiance_samples ||
        prepared->sheen_tilt_degrees != opt.sheen_tilt_degrees ||
        prepared->shadows != opt.shadows || !SameVisibility(prepared->visibility, opt.visibility) ||
        prepared->ibl_engine != opt.ibl_engine || prepared->woven_ibl != opt.start.woven.ibl ||
        prepared->env_sun != opt.env_sun || prepared->env_sun_default != opt.env_sun_default ||
        prepared->fis_taps != opt.start.woven.fis_taps ||
        prepared->fis_diffuse_taps != opt.start.woven.fis_diffuse_taps ||
        prepared->yarn_far_field != opt.yarn_far_field || prepared->yarn_table != opt.yarn_table ||
        prepared->yarn_table_ibl_only != opt.yarn_table_ibl_only ||
        prepared->yarn_quadrature_nodes != opt.yarn_quadrature_nodes ||
        prepared->yarn_ibl_bins != opt.yarn_ibl_bins || prepared->yarn_lobe != opt.start.yarn_lobe)
      throw FitError("fit: the prepared scenes were built with other options");
  } else {
    own = PrepareScenes(inputs, opt);
    prepared = own.get();
  }
  const SceneList& data = prepared->data;

  FitResult best;
  best.usable = false;
  best.message = "no start converged to a usable solution";
  const double setup = SecondsSince(t0);

  const Rgb<double> ref_colour = StartColour(*inputs[0].reference);
  double best_start_rmse = std::numeric_limits<double>::infinity();
  std::vector<ParamBlocks> points;  // the start points, each once (identical ones run once)
  const auto add = [&points](ParamBlocks blocks) {
    if (std::find(points.begin(), points.end(), blocks) == points.end())
      points.push_back(std::move(blocks));
  };
  for (double r0 : opt.start_roughness) add(StartBlocks(table, opt, r0, ref_colour));
  // physical-aniso (session 26): its strength starts at 0.5 (ApplyModelDefaults), and from
  // there an isotropic reference can stop anisotropic (a glossy synthetic truth at strength 0:
  // 0.38, RMSE 0.021). One more start, the lowest start roughness at strength 0.05, reaches
  // the isotropic basin (docs/fitting.md "A start for glossy references").
  const int strength_block = BlockIndex(table, "anisotropy_strength");
  if (opt.start.model == render::ModelKind::kPhysicalAniso && strength_block >= 0 &&
      opt.init_from_reference && !IsLocked(opt, "anisotropy_strength") && !points.empty()) {
    const double r_iso =
        *std::min_element(opt.start_roughness.begin(), opt.start_roughness.end());
    ParamBlocks iso = StartBlocks(table, opt, r_iso, ref_colour);
    iso[size_t(strength_block)][0] = 0.05;
    add(std::move(iso));
  }
  for (ParamBlocks& blocks : points) {
    const ceres::Solver::Summary summary = SolveStart(data, table, sizes, opt, blocks);
    ++best.starts;
    best.iterations += int(summary.iterations.size());
    if (!summary.IsSolutionUsable() || !AllFinite(blocks)) continue;
    // Starts are compared by the unweighted RMSE in the fit space (the error reported to the
    // user), not by the robust weighted cost each start minimised: the two can disagree when
    // the loss discounts different blocks in different solutions.
    const double start_rmse = RmseOverScenes(data, Flatten(blocks).data());
    if (!best.usable || start_rmse < best_start_rmse) {
      best_start_rmse = start_rmse;
      TakeStart(best, summary, opt, blocks);
    }
  }
  best.setup_seconds = setup;
  if (!best.usable) {
    best.seconds = SecondsSince(t0);
    return best;
  }
  best.at_bound = ParametersAtBounds(best.preset, opt.locked);
  ApplyNoEffect(opt, &best);
  AddSceneErrors(data, best);
  best.seconds = SecondsSince(t0);
  return best;
}

}  // namespace

}  // namespace clothfit::fit
