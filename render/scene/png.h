// render/scene/png.h: a minimal PNG encoder (8-bit greyscale / RGB / RGBA, no interlace): the
// PNGs io::WritePng8 / io::EncodePng8 write and the textures `clothfit convert` bakes
// (docs/convert.md, "Weave maps in glTF and three.js"). Decoding is in image_readers.h.
//
// Written from the PNG specification (ISO/IEC 15948:2004 / W3C PNG 2nd ed.): signature,
// IHDR, optional sRGB chunk, one IDAT (zlib stream of scanlines, each prefixed by filter type
// 0 "None"), IEND; chunk CRCs are CRC-32 over type + data (zlib's crc32, the same polynomial).
// The exact bytes matter for the textures: a colour texture carries an sRGB chunk, a data
// texture (anisotropy directions and strengths) must carry NO colour chunk at all (no gAMA /
// sRGB / iCCP), so that no decoder applies a transfer curve to values that are linear by
// definition (KHR_materials_anisotropy).
#pragma once

#include <string>
#include <vector>

namespace clothfit::io {

// `pixels`: width x height x channels bytes, rows top first (PNG order), channels 1, 3 or 4.
// `srgb_chunk`: write an sRGB chunk (rendering intent 0, perceptual). Throws
// std::invalid_argument on a size mismatch, std::runtime_error if zlib fails.
std::string EncodePng(int width, int height, int channels, const std::vector<unsigned char>& pixels,
                      bool srgb_chunk);

}  // namespace clothfit::io
