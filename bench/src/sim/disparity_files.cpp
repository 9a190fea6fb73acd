#include "stereo_occupancy/sim/disparity_files.h"

#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace stereo_occupancy {

namespace {

bool hostIsLittleEndian() {
  const uint16_t one = 1;
  uint8_t first;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

bool endsWith(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  std::string tail = s.substr(s.size() - suffix.size());
  for (auto& ch : tail) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return tail == suffix;
}

}  // namespace

cv::Mat readPfm(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open '" + path + "'");
  std::string magic;
  int width = 0, height = 0;
  double scale = 0.0;
  in >> magic >> width >> height >> scale;
  if (!in || magic != "Pf")
    throw std::runtime_error("'" + path + "' is not a single-channel PFM file (expected header 'Pf')");
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536 || scale == 0.0 || !std::isfinite(scale))
    throw std::runtime_error("'" + path + "' has an invalid PFM header");
  in.get();  // the single whitespace after the scale
  const bool file_little = scale < 0.0;
  std::vector<float> buffer(static_cast<size_t>(width) * height);
  in.read(reinterpret_cast<char*>(buffer.data()), static_cast<std::streamsize>(buffer.size() * sizeof(float)));
  if (in.gcount() != static_cast<std::streamsize>(buffer.size() * sizeof(float)))
    throw std::runtime_error("'" + path + "' is truncated");
  if (file_little != hostIsLittleEndian()) {
    for (float& v : buffer) {
      uint32_t u;
      std::memcpy(&u, &v, 4);
      u = __builtin_bswap32(u);
      std::memcpy(&v, &u, 4);
    }
  }
  cv::Mat image(height, width, CV_32FC1);
  // PFM stores the bottom row first.
  for (int y = 0; y < height; ++y)
    std::memcpy(image.ptr<float>(y), &buffer[static_cast<size_t>(height - 1 - y) * width], width * sizeof(float));
  return image;
}

void writePfm(const std::string& path, const cv::Mat& image) {
  if (image.type() != CV_32FC1) throw std::runtime_error("writePfm needs a CV_32FC1 image");
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
  out << "Pf\n" << image.cols << " " << image.rows << "\n" << (hostIsLittleEndian() ? "-1" : "1") << "\n";
  for (int y = image.rows - 1; y >= 0; --y)
    out.write(reinterpret_cast<const char*>(image.ptr<float>(y)),
              static_cast<std::streamsize>(image.cols * sizeof(float)));
  if (!out) throw std::runtime_error("failed writing '" + path + "'");
}

cv::Mat readDisparity(const std::string& path, double png_scale) {
  if (endsWith(path, ".pfm")) return readPfm(path);
  if (!endsWith(path, ".png")) throw std::runtime_error("'" + path + "': expected a .pfm or .png file");
  if (!(png_scale > 0.0 && std::isfinite(png_scale)))
    throw std::runtime_error("a 16-bit PNG needs --disparity-scale S > 0");
  const cv::Mat raw = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (raw.empty()) throw std::runtime_error("cannot read '" + path + "' as an image");
  if (raw.type() != CV_16UC1) throw std::runtime_error("'" + path + "' is not a single-channel 16-bit PNG");
  cv::Mat image;
  raw.convertTo(image, CV_32FC1, 1.0 / png_scale);
  return image;
}

}  // namespace stereo_occupancy
