// make_figures: the paper's figures from this project's code, as PNGs:
//   fig1_inverse_sensor_model.png  eq. 9 for measurements at 10, 20, 40 m (Fig. 1)
//   fig3_pyramid_levels.png        pyramid level and pixel footprint against disparity, 0.5 m grid (Fig. 3)
//   fig5_blur.png                  a horizontal slice of a local grid before and after the eq. 17 blur (Fig. 5)
// No roscore needed.

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include "stereo_occupancy/disparity_drawer.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "tool_support.h"

namespace so = stereo_occupancy;

namespace {

/// cv::imwrite that fails loudly.
void writeImage(const std::string& path, const cv::Mat& image) {
  if (!cv::imwrite(path, image)) throw std::runtime_error("cannot write '" + path + "'");
}

}  // namespace

namespace {

/// A minimal 2D plot: axes with ticks and labels, polylines in data units.
class Plot {
 public:
  Plot(double x0, double x1, double y0, double y1, const std::string& x_label, const std::string& y_label)
      : x0_(x0), x1_(x1), y0_(y0), y1_(y1), image_(kHeight, kWidth, CV_8UC3, cv::Scalar(255, 255, 255)) {
    const cv::Scalar black(0, 0, 0), grey(210, 210, 210);
    for (int i = 0; i <= 10; ++i) {
      const double x = x0 + (x1 - x0) * i / 10.0, y = y0 + (y1 - y0) * i / 10.0;
      cv::line(image_, px(x, y0), px(x, y1), grey, 1);
      cv::line(image_, px(x0, y), px(x1, y), grey, 1);
      cv::putText(image_, label(x), px(x, y0) + cv::Point(-12, 22), cv::FONT_HERSHEY_SIMPLEX, 0.45, black, 1,
                  cv::LINE_AA);
      cv::putText(image_, label(y), px(x0, y) + cv::Point(-52, 5), cv::FONT_HERSHEY_SIMPLEX, 0.45, black, 1,
                  cv::LINE_AA);
    }
    cv::rectangle(image_, px(x0, y1), px(x1, y0), black, 1);
    cv::putText(image_, x_label, cv::Point(kLeft + (kWidth - kLeft - kRight) / 2 - 60, kHeight - 12),
                cv::FONT_HERSHEY_SIMPLEX, 0.55, black, 1, cv::LINE_AA);
    cv::putText(image_, y_label, cv::Point(8, kTop - 10), cv::FONT_HERSHEY_SIMPLEX, 0.55, black, 1, cv::LINE_AA);
  }

  void curve(const std::vector<cv::Point2d>& points, const cv::Scalar& colour, bool dotted = false, int width = 2) {
    for (size_t i = 1; i < points.size(); ++i) {
      if (dotted && (i / 4) % 2) continue;
      cv::line(image_, px(points[i - 1].x, points[i - 1].y), px(points[i].x, points[i].y), colour, width, cv::LINE_AA);
    }
  }

  void legend(int row, const std::string& text, const cv::Scalar& colour) {
    const cv::Point p(kWidth - kRight - 250, kTop + 20 + 22 * row);
    cv::line(image_, p, p + cv::Point(30, 0), colour, 2, cv::LINE_AA);
    cv::putText(image_, text, p + cv::Point(38, 5), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }

  void title(const std::string& text) {
    cv::putText(image_, text, cv::Point(kLeft, 22), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }

  const cv::Mat& image() const { return image_; }

 private:
  static constexpr int kWidth = 900, kHeight = 520, kLeft = 70, kRight = 30, kTop = 60, kBottom = 50;
  cv::Point px(double x, double y) const {
    const double u = kLeft + (x - x0_) / (x1_ - x0_) * (kWidth - kLeft - kRight);
    const double v = kHeight - kBottom - (y - y0_) / (y1_ - y0_) * (kHeight - kTop - kBottom);
    return cv::Point(static_cast<int>(std::lround(u)), static_cast<int>(std::lround(v)));
  }
  static std::string label(double v) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), std::abs(v - std::round(v)) < 1e-9 ? "%.0f" : "%.2f", v);
    return buf;
  }
  double x0_, x1_, y0_, y1_;
  cv::Mat image_;
};

const cv::Scalar kBlue(200, 80, 0), kGreen(40, 160, 40), kRed(40, 40, 220), kBlack(0, 0, 0);

void figure1(const std::string& path) {
  const so::InverseSensorModel model{so::InverseSensorModelConfig()};
  const so::StereoCameraModel camera{so::StereoCameraConfig()};
  Plot plot(0.0, 50.0, 0.3, 0.7, "distance l along the optical axis [m]", "P(s(l))");
  plot.title("Fig. 1: eq. 9 on the optical axis; k = 0.1, p_min = 0.35, b = 0.3 m, f = 700 px, dd = 0.5 px");
  const double ranges[] = {10.0, 20.0, 40.0};
  const cv::Scalar colours[] = {kBlue, kGreen, kRed};
  for (int i = 0; i < 3; ++i) {
    std::vector<cv::Point2d> pts;
    const double dl = camera.depthUncertainty(ranges[i]);
    for (double l = 0.0; l <= 50.0; l += 0.02) pts.emplace_back(l, model.probability(l, ranges[i], dl));
    plot.curve(pts, colours[i]);
    plot.legend(i, "l_p = " + std::to_string(static_cast<int>(ranges[i])) + " m", colours[i]);
  }
  writeImage(path, plot.image());
}

void figure3(const std::string& path) {
  const so::StereoCameraModel camera{so::StereoCameraConfig()};
  const double c = 0.5;
  const so::PyramidLevelTable levels(camera, c);
  Plot plot(0.0, 64.0, 0.0, 1.2, "disparity d [px]", "footprint [m], level i x 0.2");
  plot.title("Fig. 3: pyramid level (eqs. 12-13) per disparity; c = 0.5 m, b = 0.3 m, f = 700 px");
  std::vector<cv::Point2d> one_pixel, block, level;
  for (double d = 0.5; d <= 64.0; d += 0.05) {
    const double z = camera.depthFromDisparity(d);
    const int i = levels.levelForDisparity(static_cast<float>(d));
    one_pixel.emplace_back(d, std::min(1.2, z / 700.0));                   // eq. 12, i = 0
    block.emplace_back(d, std::min(1.2, z * std::ldexp(1.0, i) / 700.0));  // eq. 12 at the chosen level
    level.emplace_back(d, 0.2 * i);
  }
  plot.curve(one_pixel, kBlack, /*dotted=*/true);
  plot.curve(block, kBlue);
  plot.curve(level, kRed);
  plot.curve({{0.0, c}, {64.0, c}}, kGreen, true, 1);
  plot.curve({{0.0, 0.5 * c}, {64.0, 0.5 * c}}, kGreen, true, 1);
  plot.legend(0, "1-pixel footprint z/f", kBlack);
  plot.legend(1, "2^i-pixel footprint (eq. 12)", kBlue);
  plot.legend(2, "level i (x 0.2)", kRed);
  plot.legend(3, "0.5 c and c (eq. 13)", kGreen);
  writeImage(path, plot.image());
}

void figure5(const std::string& path) {
  so::StereoCameraConfig camera;
  Eigen::Isometry3d T;
  const cv::Mat image = so::table1Image(so::StereoCameraModel(camera), &T);
  so::DrawingConfig config;
  config.algorithm = so::DrawingAlgorithm::kRayTracePyramid;
  config.resolution_m = 0.25;
  config.blur.sigma_trans_m = 0.1;
  config.blur.sigma_angle_rad = 0.02;
  so::DisparityDrawer drawer(camera, config);
  so::LocalGrid before, after;
  drawer.prepareGrid(T, &before);
  drawer.drawInto(image, T, &before);
  after = before;
  drawer.blur(T, &after);
  // The horizontal slice through the camera, as in the paper's 2D view: x up, y to the left.
  const int k = so::LocalGrid::globalIndex(T.translation(), 0.25).z() - before.originIndex().z();
  auto slice = [&](const so::LocalGrid& g) {
    cv::Mat out(g.size().x(), g.size().y(), CV_8UC3);
    for (int x = 0; x < g.size().x(); ++x)
      for (int y = 0; y < g.size().y(); ++y) {
        const float v = g.at(x, y, k);
        const double p = v == so::LocalGrid::kUnknown ? 0.5 : 1.0 / (1.0 + std::exp(-v));
        const auto grey = static_cast<uchar>(std::lround(255.0 * (1.0 - p)));  // darker: more occupied
        out.at<cv::Vec3b>(g.size().x() - 1 - x, g.size().y() - 1 - y) =
            v == so::LocalGrid::kUnknown ? cv::Vec3b(200, 190, 170) : cv::Vec3b(grey, grey, grey);
      }
    cv::Mat big;
    cv::resize(out, big, cv::Size(), 4.0, 4.0, cv::INTER_NEAREST);
    return big;
  };
  const cv::Mat a = slice(before), b = slice(after);
  cv::Mat both(a.rows + 40, a.cols * 2 + 20, CV_8UC3, cv::Scalar(255, 255, 255));
  a.copyTo(both(cv::Rect(0, 40, a.cols, a.rows)));
  b.copyTo(both(cv::Rect(a.cols + 20, 40, b.cols, b.rows)));
  cv::putText(both, "pyramidal ray tracing, slice at the camera's height", cv::Point(5, 25), cv::FONT_HERSHEY_SIMPLEX,
              0.5, kBlack, 1, cv::LINE_AA);
  cv::putText(both, "+ blur, s_trans 0.1 m, s_angle 0.02 rad (eq. 17)", cv::Point(a.cols + 25, 25),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, kBlack, 1, cv::LINE_AA);
  writeImage(path, both);
}

}  // namespace

int main(int argc, char** argv) {
  return so::tools::runTool("make_figures", [&] {
    if (argc > 2 || (argc == 2 && std::string(argv[1]).rfind("--", 0) == 0)) {
      if (argc == 2 && std::string(argv[1]) == "--help") {
        std::cout << "usage: make_figures [DIR]  (writes Figs. 1, 3 and 5 of the paper as PNG files)\n";
        return 0;
      }
      throw so::tools::UsageError("expects at most one argument, the output directory");
    }
    const std::string dir = argc > 1 ? argv[1] : ".";
    figure1(dir + "/fig1_inverse_sensor_model.png");
    figure3(dir + "/fig3_pyramid_levels.png");
    figure5(dir + "/fig5_blur.png");
    std::cout << "wrote " << dir << "/fig1_inverse_sensor_model.png, fig3_pyramid_levels.png, fig5_blur.png"
              << std::endl;
    return 0;
  });
}
