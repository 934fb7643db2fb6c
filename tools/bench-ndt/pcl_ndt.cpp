// PCL 1.13 NDT on one pre-voxelised scan pair, timed like msreg's bench:
// setInputTarget (voxel map build) + align, median of N runs.
// Usage: pcl_ndt target.pcd source.pcd x y z roll pitch yaw resolution step epsilon max_iter runs label pair
// Prints: RESULT <label> <pair> <median_ms> <iterations> <converged 0|1> <16 row-major numbers of T_target_source>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>
#include <pcl/registration/ndt.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 16) {
    std::fprintf(stderr, "usage: %s target source x y z roll pitch yaw res step eps max_iter runs label pair\n", argv[0]);
    return 2;
  }
  using Cloud = pcl::PointCloud<pcl::PointXYZ>;
  Cloud::Ptr target(new Cloud), source(new Cloud);
  if (pcl::io::loadPCDFile(argv[1], *target) != 0 || pcl::io::loadPCDFile(argv[2], *source) != 0) {
    std::fprintf(stderr, "cannot read %s or %s\n", argv[1], argv[2]);
    return 2;
  }
  const float x = std::atof(argv[3]), y = std::atof(argv[4]), z = std::atof(argv[5]);
  const float roll = std::atof(argv[6]), pitch = std::atof(argv[7]), yaw = std::atof(argv[8]);
  // Same convention as nalgebra's from_euler_angles(roll, pitch, yaw): R = Rz(yaw) Ry(pitch) Rx(roll).
  Eigen::Matrix3f rotation = (Eigen::AngleAxisf(yaw, Eigen::Vector3f::UnitZ()) *
                              Eigen::AngleAxisf(pitch, Eigen::Vector3f::UnitY()) *
                              Eigen::AngleAxisf(roll, Eigen::Vector3f::UnitX()))
                                 .toRotationMatrix();
  Eigen::Matrix4f guess = Eigen::Matrix4f::Identity();
  guess.topLeftCorner<3, 3>() = rotation;
  guess.topRightCorner<3, 1>() = Eigen::Vector3f(x, y, z);
  const int runs = std::atoi(argv[13]);
  std::vector<double> times;
  Eigen::Matrix4f result = guess;
  int iterations = 0;
  bool converged = false;
  for (int r = 0; r < runs; ++r) {
    pcl::NormalDistributionsTransform<pcl::PointXYZ, pcl::PointXYZ> ndt;
    ndt.setResolution(std::atof(argv[9]));
    ndt.setStepSize(std::atof(argv[10]));
    ndt.setTransformationEpsilon(std::atof(argv[11]));
    ndt.setMaximumIterations(std::atoi(argv[12]));
    Cloud output;
    const auto start = std::chrono::steady_clock::now();
    ndt.setInputTarget(target);
    ndt.setInputSource(source);
    ndt.align(output, guess);
    const auto stop = std::chrono::steady_clock::now();
    times.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
    result = ndt.getFinalTransformation();
    iterations = ndt.getFinalNumIteration();
    converged = ndt.hasConverged();
  }
  std::sort(times.begin(), times.end());
  std::printf("RESULT %s %s %.2f %d %d", argv[14], argv[15], times[times.size() / 2], iterations, converged ? 1 : 0);
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) std::printf(" %.9g", result(i, j));
  std::printf("\n");
  return 0;
}
