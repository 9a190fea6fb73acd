#!/usr/bin/env bash
# Makes the EuRoC V1_01 subset that test/rostest/euroc.test reads, from
# Kimera-VIO's extract (tests/data/MicroEurocDataset: a hover, and
# tests/data/ForLoopClosureDetector: moving pairs) and open_vins' ground
# truth (ov_data/euroc_mav/V1_01_easy.csv), both as git directories:
#
#   scripts/make_euroc_subset.sh KIMERA_VIO_GIT_DIR OPEN_VINS_GIT_DIR OUT_DIR
#
# The raw (distorted) images are binned 2 x 2 (376 x 240, a quarter of the
# bytes; the intrinsics scaled to match, the distortion unchanged since it
# acts on normalized coordinates), so that the subset stays a few MB.
set -euo pipefail
[ $# = 3 ] || { echo "usage: $0 KIMERA_VIO_GIT_DIR OPEN_VINS_GIT_DIR OUT_DIR" >&2; exit 2; }
kimera="$1" open_vins="$2" out="$3"
# Every 4th of the hover's 95 pairs (20 Hz): 24 pairs over its 4.7 s.
readonly kHoverStep=4
# The moving pairs' stamps, from Kimera-VIO's tests/testLoopClosureDetector.cpp
# (left_img_N.png / right_img_N.png, N = 0..3).
readonly kMovingStamps=(1403715386762142976 1403715288312143104 1403715400762142976 1403715400262142976)

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
cat >"$tmp/bin.cpp" <<'EOF'
// bin IN.png OUT.png: 2 x 2 binning (the mean of each block of four pixels).
// calib CAM0.yaml CAM1.yaml OUT.yaml: both cameras' calibration for the binned images.
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <cstdio>
#include <string>
#include <vector>
constexpr int kBin = 2;
void writeCamera(cv::FileStorage& out, const std::string& name, const std::string& path) {
  cv::FileStorage in(path, cv::FileStorage::READ);
  std::vector<double> k, d, t, resolution;
  in["intrinsics"] >> k;  // fu, fv, cu, cv of the full images
  in["distortion_coefficients"] >> d;
  in["T_BS"]["data"] >> t;
  in["resolution"] >> resolution;
  // Binned pixel j covers full pixels kBin*j .. kBin*j + kBin - 1: its centre
  // is at kBin*j + (kBin - 1)/2 in full-image coordinates.
  const double shift = 0.5 * (kBin - 1);
  out << name << "{";
  out << "resolution" << std::vector<int>{int(resolution[0]) / kBin, int(resolution[1]) / kBin};
  out << "intrinsics" << std::vector<double>{k[0] / kBin, k[1] / kBin, (k[2] - shift) / kBin, (k[3] - shift) / kBin};
  out << "intrinsics_full" << k;
  out << "distortion_model" << "radial-tangential";
  out << "distortion_coefficients" << d;
  out << "T_BS" << cv::Mat(4, 4, CV_64F, t.data());
  out << "}";
}
int main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "";
  if (what == "bin" && argc == 4) {
    const cv::Mat in = cv::imread(argv[2], cv::IMREAD_GRAYSCALE);
    if (in.empty()) return 1;
    cv::Mat binned;
    cv::resize(in, binned, cv::Size(in.cols / kBin, in.rows / kBin), 0, 0, cv::INTER_AREA);
    return cv::imwrite(argv[3], binned, {cv::IMWRITE_PNG_COMPRESSION, 9}) ? 0 : 1;
  }
  if (what == "calib" && argc == 5) {
    cv::FileStorage out(argv[4], cv::FileStorage::WRITE);
    out.writeComment("EuRoC V1_01 cam0/cam1 (VI-Sensor, MT9M034) from Kimera-VIO's MicroEurocDataset sensor.yaml,\n"
                     "for images binned 2 x 2: intrinsics [fu, fv, cu, cv] of the binned images\n"
                     "(intrinsics_full: the source's); distortion unchanged (normalized coordinates);\n"
                     "T_BS: the camera's pose in the body (IMU) frame, row-major [m].");
    out << "binning" << kBin;
    writeCamera(out, "cam0", argv[2]);
    writeCamera(out, "cam1", argv[3]);
    return 0;
  }
  std::fprintf(stderr, "usage: bin IN OUT | calib CAM0 CAM1 OUT\n");
  return 2;
}
EOF
# shellcheck disable=SC2046
g++ -std=c++17 -O2 "$tmp/bin.cpp" -o "$tmp/bin" $(pkg-config --cflags --libs opencv4)

show() { git --git-dir="$1" show "HEAD:$2"; }
micro=tests/data/MicroEurocDataset/mav0
mkdir -p "$out"/{hover,moving}/{cam0,cam1}
show "$kimera" "$micro/cam0/sensor.yaml" >"$tmp/cam0.yaml"
show "$kimera" "$micro/cam1/sensor.yaml" >"$tmp/cam1.yaml"
"$tmp/bin" calib "$tmp/cam0.yaml" "$tmp/cam1.yaml" "$out/calibration.yaml"
show "$kimera" tests/data/MicroEurocDataset/LICENSE.md >"$out/LICENSE.md"

stamps=()
echo "set,timestamp_ns" >"$out/frames.csv"
mapfile -t hover < <(show "$kimera" "$micro/cam0/data.csv" | grep -v '^#' | cut -d, -f1 | tr -d '\r' | awk "NR % $kHoverStep == 1")
for stamp in "${hover[@]}"; do
  for cam in cam0 cam1; do
    show "$kimera" "$micro/$cam/data/$stamp.png" >"$tmp/in.png"
    "$tmp/bin" bin "$tmp/in.png" "$out/hover/$cam/$stamp.png"
  done
  echo "hover,$stamp" >>"$out/frames.csv"
  stamps+=("$stamp")
done
for n in "${!kMovingStamps[@]}"; do
  stamp="${kMovingStamps[$n]}"
  for side in left:cam0 right:cam1; do
    show "$kimera" "tests/data/ForLoopClosureDetector/${side%%:*}_img_$n.png" >"$tmp/in.png"
    "$tmp/bin" bin "$tmp/in.png" "$out/moving/${side##*:}/$stamp.png"
  done
  echo "moving,$stamp" >>"$out/frames.csv"
  stamps+=("$stamp")
done

# The ground truth at exactly these stamps (vicon2gt gives one pose per image).
truth="$(show "$open_vins" ov_data/euroc_mav/V1_01_easy.csv)"
head -n 1 <<<"$truth" >"$out/poses.csv"
for stamp in "${stamps[@]}"; do
  grep -m 1 "^$stamp," <<<"$truth" >>"$out/poses.csv" || { echo "no pose at $stamp" >&2; exit 1; }
done
kimera_commit="$(git --git-dir="$kimera" rev-parse HEAD)"
open_vins_commit="$(git --git-dir="$open_vins" rev-parse HEAD)"
cat >"$out/README.md" <<README
# EuRoC V1_01: a subset for test/rostest/euroc.test

Data only, no code: a few stereo pairs of the EuRoC MAV dataset's sequence
V1_01_easy (ETH Zurich, Autonomous Systems Lab; Burri et al., IJRR 2016), the
cameras' calibration and the ground-truth poses at those images. Made by
stereo_occupancy's \`scripts/make_euroc_subset.sh\` from:

| what | repository | commit | path |
| --- | --- | --- | --- |
| ${#hover[@]} hover pairs (every ${kHoverStep}th of 95 at 20 Hz, 4.7 s at the start of the flight with the MAV at rest), both cameras' calibration | MIT-SPARK/Kimera-VIO | $kimera_commit | tests/data/MicroEurocDataset/mav0/cam0, cam1 |
| ${#kMovingStamps[@]} moving pairs (left_img_N / right_img_N, N = 0..3; their stamps from tests/testLoopClosureDetector.cpp) | MIT-SPARK/Kimera-VIO | $kimera_commit | tests/data/ForLoopClosureDetector |
| ground truth (vicon2gt: the IMU's pose in the vicon frame at each image) | rpng/open_vins | $open_vins_commit | ov_data/euroc_mav/V1_01_easy.csv |

- \`hover/cam0|cam1/<stamp>.png\`, \`moving/cam0|cam1/<stamp>.png\`: the raw
  (distorted) 752 x 480 images binned 2 x 2 to 376 x 240 (the mean of each
  block of four pixels), named by their stamp [ns].
- \`calibration.yaml\`: both cameras (OpenCV FileStorage): the binned
  images' intrinsics (fu/2, fv/2, (cu - 0.5)/2, (cv - 0.5)/2), the source's
  intrinsics, the radial-tangential distortion (unchanged: it acts on
  normalized coordinates), T_BS (the camera in the body frame).
- \`poses.csv\`: open_vins' header and its rows at exactly these stamps
  (time [ns], position [m], quaternion w x y z, then velocity and biases).
- \`frames.csv\`: the pairs, \`hover\` or \`moving\`, with their stamps.

Licences: the EuRoC dataset is ETH Zurich ASL's. Kimera-VIO's
tests/data/MicroEurocDataset/LICENSE.md (copied here as LICENSE.md) says only
"Dataset belongs to ASL/ETHZ" and points to the dataset's page, whose terms
apply. Kimera-VIO's code is BSD-2-Clause (LICENSE.BSD), open_vins' GPL-3.0
(LICENSE); neither repository states other terms for these data files, and
none of their code is taken.
README
echo "made $out: ${#hover[@]} hover and ${#kMovingStamps[@]} moving pairs, $(du -sh "$out" | cut -f1)"
