#include "fit/bench_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <ctime>
#include <map>
#include <sstream>

#include "fit/metrics/plot.h"
#include "fit/woven_fit.h"
#include "render/scene/image_io.h"

namespace clothfit::fit {

double CommonError(const std::vector<SceneInput>& inputs, const render::MaterialPreset& preset) {
  const int B = 16;
  double total = 0.0;
  int scenes = 0;
  for (const SceneInput& in : inputs) {
    const render::Scene& s = *in.scene;
    const Reference& ref = *in.reference;
    render::PreviewOptions o;
    o.model = preset.model;
    o.cloth = preset.cloth;
    auto cache = render::PreviewCache::Build(s, in.environment, o);
    std::vector<Rgb<double>> px;
    render::EvaluatePreview(*cache, preset.values.data(), px);
    const std::vector<float> frame = render::ComposeFrame(*cache, px);
    const auto op = render::ParseToneMapping(s.card.tone_mapping);
    const int W = s.card.width, H = s.card.height;
    double se = 0.0;
    int n = 0;
    for (int by = 0; by + B <= H; by += B)
      for (int bx = 0; bx + B <= W; bx += B) {
        bool full = true;
        Rgb<double> a(0, 0, 0), b(0, 0, 0);
        for (int y = by; y < by + B && full; ++y)
          for (int x = bx; x < bx + B; ++x) {
            const size_t p = size_t(y) * size_t(W) + size_t(x);
            if (cache->fabric_mask[p] < 0.5f || ref.fabric[p] < 0.999f) {
              full = false;
              break;
            }
            for (int c = 0; c < 3; ++c) {
              a[c] += double(frame[p * 3 + size_t(c)]);
              b[c] += double(ref.rgb[p * 3 + size_t(c)]);
            }
          }
        if (!full) continue;
        const double inv = 1.0 / double(B * B);
        const Rgb<double> da = render::ToDisplay(a * inv, op, s.card.exposure);
        const Rgb<double> db = render::ToDisplay(b * inv, op, s.card.exposure);
        for (int c = 0; c < 3; ++c) se += (da[c] - db[c]) * (da[c] - db[c]);
        n += 3;
      }
    if (n > 0) {
      total += std::sqrt(se / n);
      ++scenes;
    }
  }
  return scenes ? total / scenes : std::numeric_limits<double>::quiet_NaN();
}

std::vector<BenchRow> RunFitBench(const std::string& fabric,
                                  const std::function<std::vector<SceneInput>(int width)>& inputs_at,
                                  const std::vector<SceneInput>& common, double weave_period_uv,
                                  const FitOptions& base, const std::vector<BenchSetting>& settings,
                                  const std::function<void(const BenchRow&)>& log) {
  std::vector<BenchRow> rows;
  std::map<int, std::vector<SceneInput>> by_width;  // fit inputs per resolution, built once
  std::map<int, int> auto_level;
  for (const BenchSetting& st : settings) {
    auto it = by_width.find(st.width);
    if (it == by_width.end()) {
      it = by_width.emplace(st.width, inputs_at(st.width)).first;
      auto_level[st.width] = AutoLevel(it->second, weave_period_uv);
    }
    const std::vector<SceneInput>& inputs = it->second;
    FitOptions o = base;
    o.level = st.level >= 0 ? st.level : auto_level[st.width];
    o.pixel_stride = st.stride;
    // Nested start sets, so more starts can only find a lower fit-space error.
    o.start_roughness = st.starts == 1   ? std::vector<double>{0.6}
                        : st.starts == 2 ? std::vector<double>{0.6, 0.9}
                                         : std::vector<double>{0.6, 0.9, 0.3};
    BenchRow row;
    row.fabric = fabric;
    row.setting = st;
    row.width = inputs.empty() ? 0 : inputs.front().scene->card.width;
    row.level = o.level;
    const auto t0 = std::chrono::steady_clock::now();
    FitResult r;
    try {
      r = FitImages(inputs, o);
    } catch (const FitError&) {
      r.usable = false;  // e.g. no full block at a large level: reported as unusable
    }
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    row.usable = r.usable;
    row.error = r.usable ? CommonError(common, r.preset) : std::numeric_limits<double>::quiet_NaN();
    if (log) log(row);
    rows.push_back(row);
  }
  return rows;
}

std::vector<ModelRow> RunModelBench(const std::string& fabric,
                                    const std::vector<SceneInput>& inputs,
                                    double weave_period_uv,
                                    const std::vector<render::ModelKind>& models,
                                    const std::function<void(const ModelRow&)>& log,
                                    const std::string& fabric_path) {
  std::vector<ModelRow> rows;
  const int level = AutoLevel(inputs, weave_period_uv);
  for (render::ModelKind m : models) {
    FitOptions o;
    o.start = render::DefaultPreset(m);
    o.level = level;
    ApplyModelDefaults(&o);  // as clothfit fit
    ModelRow row;
    row.fabric = fabric;
    row.model = render::ToString(m);
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    FitResult r;
    try {
      if (m == render::ModelKind::kWoven) {
        o.start_roughness = {0.6, 0.3};  // the `clothfit fit` default for woven
        if (!fabric_path.empty()) {
          const std::filesystem::path maps = std::filesystem::temp_directory_path() /
                                             ("clothfit-bench-" + fabric + ".weave.exr");
          (void)AttachWeaveMaps(fabric_path, maps.string(), &o);
          (void)SetMapAnisotropy(kDefaultMapAnisotropy, &o);  // as clothfit fit's default
        }
        r = FitWovenImages(inputs, o);
      } else if (m == render::ModelKind::kPhysicalAniso) {
        if (!fabric_path.empty()) {  // the same maps as woven, baked as clothfit fit does
          const std::filesystem::path maps = std::filesystem::temp_directory_path() /
                                             ("clothfit-bench-" + fabric + ".aniso.weave.exr");
          (void)AttachWeaveMapsToPhysicalAniso(fabric_path, maps.string(), &o);
          (void)SetMapAnisotropy(kDefaultMapAnisotropy, &o);  // as clothfit fit's default
        }
        r = FitImages(inputs, o);
      } else {
        r = FitImages(inputs, o);
      }
    } catch (const FitError&) {
      r.usable = false;
    }
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    row.cpu_seconds = double(std::clock() - c0) / double(CLOCKS_PER_SEC);
    row.usable = r.usable;
    row.iterations = r.iterations;
    row.starts = r.starts;
    row.termination = r.termination;
    row.fit_rmse = r.rmse;
    row.error = r.usable ? CommonError(inputs, r.preset) : std::numeric_limits<double>::quiet_NaN();
    if (log) log(row);
    rows.push_back(row);
  }
  return rows;
}

void WriteModelBench(const std::vector<ModelRow>& rows, const std::string& csv_path) {
  std::ostringstream csv;
  csv << "fabric,model,seconds,cpu_seconds,error,fit_rmse,iterations,starts,termination,usable\n";
  for (const ModelRow& r : rows)
    csv << r.fabric << "," << r.model << "," << r.seconds << "," << r.cpu_seconds << "," << r.error << "," << r.fit_rmse
        << "," << r.iterations << "," << r.starts << "," << r.termination << ","
        << (r.usable ? 1 : 0) << "\n";
  io::WriteTextAtomic(csv_path, csv.str());
}

namespace {

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string CurveName(const BenchRow& r) {
  return std::string("stride ") + (r.setting.stride == 0 ? "auto" : std::to_string(r.setting.stride)) +
         ", " + std::to_string(r.setting.starts) + (r.setting.starts == 1 ? " start" : " starts");
}

}  // namespace

void WriteFitBench(const std::vector<BenchRow>& rows, const std::string& csv_path,
                   const std::string& png_path) {
  std::ostringstream csv;
  csv << "fabric,width,level,stride,starts,seconds,error,usable\n";
  for (const BenchRow& r : rows) {
    csv << r.fabric << "," << r.width << "," << r.level << "," << r.setting.stride << ","
        << r.setting.starts << "," << r.seconds << "," << r.error << "," << (r.usable ? 1 : 0) << "\n";
  }
  io::WriteTextAtomic(csv_path, csv.str());

  // One panel per fabric; one curve per (stride, starts) across resolutions.
  std::vector<std::string> fabrics;
  std::vector<std::string> curves;
  for (const BenchRow& r : rows) {
    if (std::find(fabrics.begin(), fabrics.end(), r.fabric) == fabrics.end()) fabrics.push_back(r.fabric);
    if (std::find(curves.begin(), curves.end(), CurveName(r)) == curves.end()) curves.push_back(CurveName(r));
  }
  const int PW = 460, PH = 360, L = 70, T = 40, B = 50, legend_h = 24 * int((curves.size() + 2) / 3) + 20;
  const int W = std::max(940, std::max<int>(1, int(fabrics.size())) * (PW + L) + 20);
  const int H = T + PH + B + legend_h;
  Canvas cv(W, H);
  const Colour black{0, 0, 0}, grey{0.85f, 0.85f, 0.85f}, dark{0.3f, 0.3f, 0.3f};
  const Colour palette[6] = {{0.85f, 0.1f, 0.1f}, {0.1f, 0.45f, 0.85f}, {0.1f, 0.6f, 0.2f},
                             {0.8f, 0.5f, 0.0f},  {0.5f, 0.2f, 0.7f},   {0.3f, 0.3f, 0.3f}};
  cv.Text(10, 22, "clothfit bench fit: error (display RMSE at the card resolution) vs fit wall time", 16, black);
  for (size_t f = 0; f < fabrics.size(); ++f) {
    const int x0 = int(f) * (PW + L) + L, y0 = T;  // panel's top-left
    double tmin = 1e30, tmax = 0, emin = 1e30, emax = 0;
    for (const BenchRow& r : rows) {
      if (r.fabric != fabrics[f] || !r.usable || !std::isfinite(r.error)) continue;
      tmin = std::min(tmin, r.seconds);
      tmax = std::max(tmax, r.seconds);
      emin = std::min(emin, r.error);
      emax = std::max(emax, r.error);
    }
    if (tmax <= 0) tmin = 0.1, tmax = 1, emin = 0, emax = 1;
    const double lt0 = std::log(tmin / 1.3), lt1 = std::log(tmax * 1.3);
    const double pad = std::max(1e-6, 0.06 * (emax - emin));
    const double e0 = emin - pad, e1 = emax + pad;
    auto X = [&](double t) { return x0 + int((std::log(t) - lt0) / (lt1 - lt0) * PW); };
    auto Y = [&](double e) { return y0 + PH - int((e - e0) / (e1 - e0) * PH); };
    for (double t : LogTicks(std::exp(lt0), std::exp(lt1))) {
      cv.Line(X(t), y0, X(t), y0 + PH, grey);
      cv.Text(X(t) - 8, y0 + PH + 16, t < 1 ? Fmt("%.1f", t) : Fmt("%.0f", t), 12, dark);
    }
    for (double e : LinearTicks(e0, e1, 6)) {
      cv.Line(x0, Y(e), x0 + PW, Y(e), grey);
      cv.Text(x0 - 52, Y(e) + 4, Fmt("%.4f", e), 12, dark);
    }
    cv.Line(x0, y0 + PH, x0 + PW, y0 + PH, black);
    cv.Line(x0, y0, x0, y0 + PH, black);
    cv.Text(x0 + 4, y0 + 14, fabrics[f], 14, black);
    cv.Text(x0 + PW / 2 - 30, y0 + PH + 34, "seconds", 12, dark);
    for (size_t c = 0; c < curves.size(); ++c) {
      std::vector<const BenchRow*> list;
      for (const BenchRow& r : rows)
        if (r.fabric == fabrics[f] && CurveName(r) == curves[c] && r.usable && std::isfinite(r.error))
          list.push_back(&r);
      std::sort(list.begin(), list.end(),
                [](const BenchRow* a, const BenchRow* b) { return a->width < b->width; });
      const Colour& col = palette[c % 6];
      for (size_t i = 0; i < list.size(); ++i) {
        cv.Dot(X(list[i]->seconds), Y(list[i]->error), col, 3);
        if (i > 0)
          cv.Line(X(list[i - 1]->seconds), Y(list[i - 1]->error), X(list[i]->seconds),
                  Y(list[i]->error), col);
        if (c == 0)  // resolution labels on the first curve
          cv.Text(X(list[i]->seconds) + 5, Y(list[i]->error) - 5, std::to_string(list[i]->width) + "px",
                  11, col);
      }
    }
  }
  for (size_t c = 0; c < curves.size(); ++c) {
    const int lx = 20 + int(c % 3) * 300, ly = T + PH + B + 10 + 24 * int(c / 3);
    cv.Line(lx, ly, lx + 24, ly, palette[c % 6]);
    cv.Dot(lx + 12, ly, palette[c % 6], 3);
    cv.Text(lx + 32, ly + 5, curves[c], 13, black);
  }
  cv.WritePng(png_path);
}

}  // namespace clothfit::fit
