#include "fit/bench_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "render/image_io.h"

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

std::vector<BenchRow> RunFitBench(const std::string& fabric, const std::vector<SceneInput>& inputs,
                                  const FitOptions& base, const std::vector<BenchSetting>& settings,
                                  const std::function<void(const BenchRow&)>& log) {
  std::vector<BenchRow> rows;
  for (const BenchSetting& st : settings) {
    FitOptions o = base;
    o.level = st.level;
    o.pixel_stride = st.stride;
    // Nested start sets, so more starts can only find a lower fit-space error.
    o.start_roughness = st.starts == 1   ? std::vector<double>{0.6}
                        : st.starts == 2 ? std::vector<double>{0.6, 0.9}
                                         : std::vector<double>{0.6, 0.9, 0.3};
    BenchRow row;
    row.fabric = fabric;
    row.setting = st;
    const auto t0 = std::chrono::steady_clock::now();
    FitResult r;
    try {
      r = FitImages(inputs, o);
    } catch (const FitError&) {
      r.usable = false;  // e.g. no full block at a large level: reported as unusable
    }
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    row.usable = r.usable;
    row.error = r.usable ? CommonError(inputs, r.preset) : std::numeric_limits<double>::quiet_NaN();
    if (log) log(row);
    rows.push_back(row);
  }
  return rows;
}

namespace {

void Plot(std::vector<float>& img, int W, int H, int x, int y, const float rgb[3], int r) {
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const int px = x + dx, py = y + dy;
      if (px < 0 || py < 0 || px >= W || py >= H) continue;
      for (int c = 0; c < 3; ++c) img[(size_t(py) * size_t(W) + size_t(px)) * 3 + size_t(c)] = rgb[c];
    }
}

void Line(std::vector<float>& img, int W, int H, int x0, int y0, int x1, int y1, const float rgb[3]) {
  const int steps = std::max(std::abs(x1 - x0), std::abs(y1 - y0)) + 1;
  for (int i = 0; i <= steps; ++i) {
    const double t = double(i) / steps;
    Plot(img, W, H, int(std::lround(x0 + t * (x1 - x0))), int(std::lround(y0 + t * (y1 - y0))), rgb, 0);
  }
}

}  // namespace

void WriteFitBench(const std::vector<BenchRow>& rows, const std::string& csv_path,
                   const std::string& png_path) {
  std::ostringstream csv;
  csv << "fabric,level,stride,starts,seconds,error,usable\n";
  for (const BenchRow& r : rows) {
    csv << r.fabric << "," << r.setting.level << "," << r.setting.stride << "," << r.setting.starts
        << "," << r.seconds << "," << r.error << "," << (r.usable ? 1 : 0) << "\n";
  }
  io::WriteTextAtomic(csv_path, csv.str());

  const int W = 640, H = 400, M = 40;
  std::vector<float> img(size_t(W) * size_t(H) * 3, 1.0f);
  double tmin = 1e30, tmax = 0, emin = 1e30, emax = 0;
  for (const BenchRow& r : rows) {
    if (!r.usable || !std::isfinite(r.error)) continue;
    tmin = std::min(tmin, r.seconds);
    tmax = std::max(tmax, r.seconds);
    emin = std::min(emin, r.error);
    emax = std::max(emax, r.error);
  }
  if (tmax <= 0) tmin = 0.1, tmax = 1, emin = 0, emax = 1;
  const double lt0 = std::log(tmin * 0.8), lt1 = std::log(tmax * 1.25);
  const double e0 = emin * 0.95, e1 = emax * 1.05 + 1e-12;
  auto X = [&](double t) { return M + int((std::log(t) - lt0) / (lt1 - lt0) * (W - 2 * M)); };
  auto Y = [&](double e) { return H - M - int((e - e0) / (e1 - e0) * (H - 2 * M)); };
  const float axis[3] = {0.f, 0.f, 0.f};
  Line(img, W, H, M, H - M, W - M, H - M, axis);
  Line(img, W, H, M, H - M, M, M, axis);
  const float palette[6][3] = {{0.85f, 0.1f, 0.1f}, {0.1f, 0.45f, 0.85f}, {0.1f, 0.6f, 0.2f},
                               {0.8f, 0.5f, 0.0f},  {0.5f, 0.2f, 0.7f},   {0.3f, 0.3f, 0.3f}};
  std::map<std::string, int> curve;
  std::map<std::string, std::vector<const BenchRow*>> members;
  for (const BenchRow& r : rows) {
    if (!r.usable || !std::isfinite(r.error)) continue;
    const std::string key = r.fabric + "/s" + std::to_string(r.setting.stride) + "/n" +
                            std::to_string(r.setting.starts);
    if (!curve.count(key)) curve[key] = int(curve.size());
    members[key].push_back(&r);
  }
  for (auto& [key, list] : members) {
    const float* col = palette[curve[key] % 6];
    std::sort(list.begin(), list.end(),
              [](const BenchRow* a, const BenchRow* b) { return a->setting.level < b->setting.level; });
    for (size_t i = 0; i < list.size(); ++i) {
      Plot(img, W, H, X(list[i]->seconds), Y(list[i]->error), col, 3);
      if (i > 0)
        Line(img, W, H, X(list[i - 1]->seconds), Y(list[i - 1]->error), X(list[i]->seconds),
             Y(list[i]->error), col);
    }
  }
  io::WritePng8(png_path, W, H, img);
}

}  // namespace clothfit::fit
