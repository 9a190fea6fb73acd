#pragma once
// A progress bar on stderr for the tools: redrawn in place only when stderr
// is a terminal; into a log or a pipe it writes nothing until the end, then
// one line.

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>

namespace stereo_occupancy {
namespace tools {

class ProgressBar {
 public:
  /// @param what the things counted ("frames").
  ProgressBar(size_t total, std::string what)
      : total_(total), what_(std::move(what)), terminal_(::isatty(STDERR_FILENO) == 1) {}

  /// @p done of the total: redraws the bar (on a terminal, at most 10 times a second).
  void update(size_t done) {
    done_ = done;
    if (!terminal_) return;
    const auto now = Clock::now();
    if (done < total_ && now - last_draw_ < std::chrono::milliseconds(kRedrawMs)) return;
    last_draw_ = now;
    std::cerr << "\r" << line() << "   " << std::flush;
  }

  /// The last state: on a terminal the bar ends its line; elsewhere one line.
  void finish() { std::cerr << (terminal_ ? "\r" : "") << line() << std::endl; }

 private:
  using Clock = std::chrono::steady_clock;
  static constexpr int kWidth = 30;      ///< characters of the bar
  static constexpr int kRedrawMs = 100;  ///< at most this often on a terminal

  std::string line() const {
    const double elapsed_s = std::chrono::duration<double>(Clock::now() - start_).count();
    const double f = total_ ? static_cast<double>(done_) / static_cast<double>(total_) : 1.0;
    const double rate = elapsed_s > 0.0 ? static_cast<double>(done_) / elapsed_s : 0.0;
    const double left_s = rate > 0.0 ? static_cast<double>(total_ - done_) / rate : 0.0;
    const int filled = static_cast<int>(f * kWidth);
    char text[160];
    std::snprintf(text, sizeof text, "] %zu/%zu %s, %.0f %s/s, %.0f s left", done_, total_, what_.c_str(), rate,
                  what_.c_str(), left_s);
    return "[" + std::string(filled, '#') + std::string(kWidth - filled, ' ') + text;
  }

  size_t total_, done_ = 0;
  std::string what_;
  bool terminal_;
  Clock::time_point start_ = Clock::now(), last_draw_;
};

}  // namespace tools
}  // namespace stereo_occupancy
