// fit/metrics/report.h: per-fabric reports of fitted presets (docs/report.md).
//
// Input: the presets `clothfit fit --images DIR` writes (docs/fitting.md). Each records, per
// scene, the reference EXR, the second-seed reference (noise floor), the scene card's display
// transform (tone mapping, exposure) and the fitted preview as a linear EXR. Presets are
// grouped by fabric; every preset of one fabric must cover the same scenes with the same
// references.
//
// Metrics (fit/metrics/metrics.h, metrics::Compare) are computed per scene between the reference and
// each model's preview over the reference's fabric pixels (coverage channel "fabric", else
// "A", > 0.5; every pixel when neither exists). The noise floor is the same comparison between
// the reference and the second-seed reference: both are noisy, so its RMSE is about sqrt(2)
// times one reference's own noise (the fit's `noise_floor` divides by sqrt(2)). Without a
// second reference, when the reference carries half channels (fit/metrics/reference_halves.h),
// the noise floor compares its two half-sample images A and B instead: each has half the
// samples, so this floor is conservative (its RMSE is about sqrt(2) x the two-seed floor's,
// 2 x the reference's own noise; docs/report.md). One HDR-FLIP
// exposure range per reference is shared by every image compared with it: the automatic range
// of the reference over the fabric pixels, or kFallbackHdrRange when that is not finite.
//
// Outputs: one self-contained HTML page per fabric (images as base64 PNG data URIs, inline CSS),
// an index page with a sortable summary table (inline JS), report.json and report.csv with the
// same numbers, and a compact terminal table. A number that cannot be computed (non-finite or
// missing input) is written "n/a (reason)" in pages and tables, null in JSON and empty in CSV
// (with the reason in its status column); NaN and Inf never reach an output. The only
// infinity is the PSNR of identical images, written "inf" (JSON: the string "inf").
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fit/metrics/metrics.h"
#include "render/scene/image_io.h"
#include "render/scene/tonemap.h"

namespace clothfit::report {

// Used when the reference's automatic HDR-FLIP range is not finite (docs/metrics.md).
inline constexpr metrics::ExposureRange kFallbackHdrRange{-6.0, 2.0};

class ReportError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SceneSpec {
  std::string name;        // e.g. "sphere" (the scene card's stem)
  std::string scene_path;  // the scene card (shown only)
  std::string reference;   // linear EXR
  std::string reference2;  // linear EXR with another seed; empty: no noise floor
  render::ToneMapping tone_mapping = render::ToneMapping::kAcesFilmic;
  double exposure = 1.0;
};

struct ModelSpec {
  std::string model;  // preset "model": cloth, physical-sheen, standard, gltf-sheen
  std::string preset_path;
  nlohmann::json preset;              // the whole preset as read
  std::vector<std::string> previews;  // linear EXRs, one per scene (FabricSpec::scenes order)
};

struct FabricSpec {
  std::string name;         // e.g. "canvas"
  std::string fabric_path;  // the fabric definition (shown only; may be empty)
  std::vector<SceneSpec> scenes;
  std::vector<ModelSpec> models;
};

// Reads fit presets and groups them by fabric (provenance.fabric's stem, else the preset
// file's stem), keeping the first-seen order. Throws ReportError naming the file and the field
// on a missing file, malformed JSON, a preset without the fields above, or presets of one
// fabric whose scenes differ.
std::vector<FabricSpec> FabricsFromPresets(const std::vector<std::string>& preset_paths);

// The numbers of one comparison. `ok` false: not computable; `why` says why.
struct Numbers {
  bool ok = false;
  std::string why;
  double rmse_linear = 0, psnr_linear = 0, rmse_display = 0, psnr_display = 0, ssim = 0;
  double flip = 0, hdr_flip = 0;
  double ciede2000_mean = 0, ciede2000_p95 = 0, ciede2000_display_mean = 0,
         ciede2000_display_p95 = 0;
  metrics::PixelCounts counts;
};

struct ModelSceneResult {
  Numbers numbers;
  std::string preview_png, flip_png;  // base64 PNG data (no "data:" prefix)
};

struct SceneResult {
  SceneSpec spec;
  int width = 0, height = 0;
  long long fabric_pixels = 0;
  bool mask_from_coverage = false;  // false: every pixel counts
  metrics::ExposureRange hdr_range;
  bool hdr_range_automatic = false;
  std::string reference_png;             // base64
  std::optional<Numbers> noise_floor;    // absent without a second reference or halves
  std::string noise_floor_source;        // kSecondReference, kReferenceHalves or ""
  std::string noise_flip_png;            // FLIP map of the noise-floor pair (base64)
  std::vector<ModelSceneResult> models;  // FabricSpec::models order
};

// Thumbnails of a preset's weave maps (its top-level "weave_maps": woven, physical-aniso).
struct WeaveMapPictures {
  std::string file;          // the map EXR as resolved
  std::string note;          // why there are no pictures (unreadable file, missing channels)
  std::string colour_space;  // the preset's weave_maps.colour_space (untrusted text)
  int size = 0;              // texels per period (the EXR's width)
  double uv_repeats = 0.0;
  struct Picture {
    int band = -1;      // -1: the main (all-views) maps; k >= 0: view band k (view{k}.*)
    std::string title;  // e.g. "warp weight"
    std::string png;    // base64, 2 x 2 periods
    double min = 0.0, max = 0.0;  // of the channel(s) over one period
    double scale = 0.0;           // display normalisation (see WeaveMapThumbnails)
  };
  std::vector<Picture> pictures;  // the main maps' first, then each view band's in order
  int view_bands = 0;              // view bands found in the file (view0.* .. view{K-1}.*)
  // A woven preset's weave_maps.view_cosines (empty for other models, without the field, or
  // when any entry is not a number in (0, 1]): the view cosine of each band the preview draws.
  // Without it the preview ignores the file's bands.
  std::vector<double> view_cosines;
};

// Tiles `periods` x `periods` copies of one period of the maps in `image` (channels warp, weft,
// kd.R/G/B; the others are ignored) into pictures, stored as 8-bit values without sRGB
// encoding: a weight (warp, weft) as value / max over the period (Picture::scale = max); the kd
// ratio as 0.5 + 0.5 (value - 1) / s per channel, s = max |value - 1| over the period and
// channels (Picture::scale = s; mid-grey = the tile mean). A period larger than 128 texels is
// subsampled (nearest) to 128. Missing channels give fewer pictures and a note. View bands
// (session 14; channels view{k}.warp, view{k}.weft, view{k}.kd.R/G/B for k = 0, 1, ... up to
// the first k with none of them, at most 8) get the same three pictures each, normalised on
// their own, with Picture::band = k.
WeaveMapPictures WeaveMapThumbnails(const io::Image& image, const std::string& file, int periods = 2);

// SceneResult::noise_floor_source values.
inline constexpr const char* kSecondReference = "second reference";
inline constexpr const char* kReferenceHalves = "reference halves";

struct FabricReport {
  FabricSpec spec;
  std::vector<SceneResult> scenes;
  std::vector<Numbers> model_means;  // mean over scenes, per model
  std::optional<Numbers> noise_floor_mean;
  std::string noise_floor_source;  // the scenes' common source, or "mixed"
  // Per model (FabricSpec::models order): its weave maps; absent without "weave_maps".
  std::vector<std::optional<WeaveMapPictures>> weave_maps;
};

// The label of a noise-floor row for a source (kSecondReference: "noise floor (second seed)",
// kReferenceHalves: "noise floor (two half-sample images of the reference)").
std::string NoiseFloorLabel(const std::string& source);

struct ReportOptions {
  double ppd = 67.0;
};

// Loads every image and computes every number and picture. Throws ReportError naming the file
// on a missing, unreadable or corrupt image, or on images of different sizes.
FabricReport BuildFabricReport(const FabricSpec& spec, const ReportOptions& options = {});

// Mean over scenes (used for model_means): each field is the mean of the scenes' values; a
// not-ok scene makes the mean not ok (naming the scene); an infinite PSNR makes the mean PSNR
// infinite.
Numbers MeanOver(const std::vector<const Numbers*>& per_scene,
                 const std::vector<std::string>& scene_names);

// The file name of a fabric's page: "<name>.html" with characters outside [A-Za-z0-9_-]
// replaced by '_' ("fabric-index.html" for a fabric named "index", "fabric-.html" for "").
std::string PageName(const std::string& fabric_name);

// `report_dir` (the directory the page is written to; empty: no viewer links): each fitted
// preset gets, per scene, a link to web/viewer.html carrying the scene card and the preset
// (ViewerLink).
std::string FabricHtml(const FabricReport& report, const std::string& report_dir = "");

// The link to the repository's web/viewer.html, served by `node web/serve.mjs` on its default
// address (kViewerOrigin), with ?preset=<path>&card=<path> as URL paths on that server: a file
// inside the repository as /<path from the repository root>, any other file as /fs/<absolute
// path> (serve.mjs serves those with --root DIR; ViewerRoots lists the directories). Absolute
// http links, so that they work from the page opened as a file as well as served (session 27:
// the relative links before broke in both cases the audit tried). Empty when no web/viewer.html
// is found above `report_dir`, the working directory or the running binary. A relative
// `scene_path` is taken from the repository root, the working directory or the preset's
// directory, whichever holds it.
inline constexpr const char* kViewerOrigin = "http://127.0.0.1:8000";
std::string ViewerLink(const std::string& report_dir, const std::string& scene_path,
                       const std::string& preset_path);

// The directories outside the repository that hold the preset or any of the scene cards (found
// as ViewerLink finds them): what `node web/serve.mjs --root DIR` must serve for ViewerLink's
// /fs/ paths (empty when every file is inside).
std::vector<std::string> ViewerRoots(const std::string& report_dir, const std::string& preset_path,
                                     const std::vector<std::string>& scene_paths);
std::string IndexHtml(const std::vector<FabricReport>& reports);
nlohmann::json ReportJson(const std::vector<FabricReport>& reports);
std::string ReportCsv(const std::vector<FabricReport>& reports);
std::string TerminalTable(const std::vector<FabricReport>& reports);

// Writes <dir>/index.html, one page per fabric, report.json and report.csv, each atomically.
// Returns the index path.
std::string WriteReport(const std::vector<FabricReport>& reports, const std::string& dir);

// Helpers exposed for tests.
std::string Base64(const std::vector<unsigned char>& bytes);
std::string Base64(const std::string& bytes);
// A number for pages and tables: "n/a (not finite in input)" for NaN, "inf"/"-inf" for
// infinities only when allow_infinity, else "n/a"; otherwise printf("%.*f").
std::string FormatNumber(double v, int decimals, bool allow_infinity = false);
// HTML-escapes &, <, >, " and '.
std::string EscapeHtml(const std::string& text);
// Linear colour -> "#rrggbb" sRGB-encoded (clamped to [0, 1]); empty for non-finite input.
std::string SrgbHex(double r, double g, double b);

}  // namespace clothfit::report
