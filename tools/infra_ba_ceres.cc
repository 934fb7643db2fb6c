// The infrastructure bundle adjustment benchmark problem (issue 14), solved by Ceres:
// the same unknowns, residuals, whitening and Cauchy loss as msreg's
// host/src/infra/ba.rs, read from the text file `infra_ba_bench gen` writes.
// Built and run by tools/infra_ba_bench.sh against Debian's libceres-dev.
//
//   infra_ba_ceres <problem.txt> <state_out.txt> [threads]
//
// Residuals (whitened px, CauchyLoss(3) on each 2-vector, as msreg):
//   keypoint  pi_F(R_k^T (X - t_k)) - uv,                              sigma 0.5
//   blob      pi_F(R_k^T (t_C - t_k)) - uv,                            sigma 1
//   corner    pi_C(T_vo_C^-1 interp(T_k_i, T_k_j, alpha) T_F_M c) - uv,  sigma 0.3
// Poses are T_vo_X as (w, x, y, z) quaternion + translation; keyframe 0 is held fixed.
// Ceres' cost is 1/2 sum rho; msreg's is sum rho (the script evaluates both solvers'
// final states with msreg's cost function).

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace {

struct Lens {
  int kind;  // 0 equidistant (k1..k4), 1 pinhole radtan (k1 k2 p1 p2)
  double fu, fv, cu, cv, d[4];
};

template <typename T>
void Project(const Lens& l, const T p[3], T px[2]) {
  T mx, my;
  if (l.kind == 0) {
    const T rho2 = p[0] * p[0] + p[1] * p[1];
    if (rho2 < T(1e-18) * p[2] * p[2]) {
      mx = p[0] / p[2];
      my = p[1] / p[2];
    } else {
      const T rho = sqrt(rho2);
      const T th = atan2(rho, p[2]);
      const T t2 = th * th;
      const T thd = th * (1.0 + t2 * (l.d[0] + t2 * (l.d[1] + t2 * (l.d[2] + t2 * l.d[3]))));
      mx = thd / rho * p[0];
      my = thd / rho * p[1];
    }
  } else {
    const T x = p[0] / p[2], y = p[1] / p[2];
    const T r2 = x * x + y * y;
    const T radial = 1.0 + r2 * (l.d[0] + r2 * l.d[1]);
    mx = x * radial + 2.0 * l.d[2] * x * y + l.d[3] * (r2 + 2.0 * x * x);
    my = y * radial + l.d[2] * (r2 + 2.0 * y * y) + 2.0 * l.d[3] * x * y;
  }
  px[0] = l.fu * mx + l.cu;
  px[1] = l.fv * my + l.cv;
}

// p = R^T (x - t) for a pose (q, t) = T_vo_X.
template <typename T>
void ToLocal(const T* q, const T* t, const T x[3], T p[3]) {
  const T qi[4] = {q[0], -q[1], -q[2], -q[3]};
  const T d[3] = {x[0] - t[0], x[1] - t[1], x[2] - t[2]};
  ceres::UnitQuaternionRotatePoint(qi, d, p);
}

struct PointCost {
  const Lens* lens;
  double u, v, inv_sigma;
  template <typename T>
  bool operator()(const T* q, const T* t, const T* x, T* r) const {
    T p[3], px[2];
    ToLocal(q, t, x, p);
    Project(*lens, p, px);
    r[0] = (px[0] - u) * inv_sigma;
    r[1] = (px[1] - v) * inv_sigma;
    return true;
  }
};

// Shortest-path slerp of unit quaternions a -> b by alpha (as nalgebra's), lerp of t.
template <typename T>
void Interp(const T* qa, const T* ta, const T* qb, const T* tb, double alpha, T q[4], T t[3]) {
  const T ia[4] = {qa[0], -qa[1], -qa[2], -qa[3]};
  T rel[4];
  ceres::QuaternionProduct(ia, qb, rel);
  if (rel[0] < T(0)) {
    for (auto& v : rel) v = -v;
  }
  T aa[3], d[4];
  ceres::QuaternionToAngleAxis(rel, aa);
  for (auto& v : aa) v *= alpha;
  ceres::AngleAxisToQuaternion(aa, d);
  ceres::QuaternionProduct(qa, d, q);
  for (int k = 0; k < 3; ++k) t[k] = ta[k] * (1.0 - alpha) + tb[k] * alpha;
}

struct CornerCost {
  const Lens* lens;
  double c[3], alpha, u, v;
  template <typename T>
  bool operator()(const T* qi, const T* ti, const T* qj, const T* tj, const T* qm,
                  const T* tm, const T* qc, const T* tc, T* r) const {
    T q[4], t[3], cm[3], cf[3], cv[3], p[3], px[2];
    Interp(qi, ti, qj, tj, alpha, q, t);
    const T cc[3] = {T(c[0]), T(c[1]), T(c[2])};
    ceres::UnitQuaternionRotatePoint(qm, cc, cm);
    for (int k = 0; k < 3; ++k) cf[k] = cm[k] + tm[k];
    ceres::UnitQuaternionRotatePoint(q, cf, cv);
    for (int k = 0; k < 3; ++k) cv[k] += t[k];
    ToLocal(qc, tc, cv, p);
    Project(*lens, p, px);
    r[0] = (px[0] - u) / 0.3;
    r[1] = (px[1] - v) / 0.3;
    return true;
  }
};

struct Pose {
  double q[4], t[3];
};

struct Problem {
  Lens f;
  std::vector<Lens> cams;
  double corners[4][3];
  std::vector<Pose> kf, cam;
  Pose tfm;
  std::vector<std::array<double, 3>> points;
  int nvo = 0, nmk = 0, nblob = 0;
};

Lens ReadLens(std::istream& in) {
  Lens l;
  int w, h;
  in >> l.kind >> w >> h >> l.fu >> l.fv >> l.cu >> l.cv >> l.d[0] >> l.d[1] >> l.d[2] >> l.d[3];
  return l;
}

void ReadPose(std::istream& in, Pose* p) {
  in >> p->q[0] >> p->q[1] >> p->q[2] >> p->q[3] >> p->t[0] >> p->t[1] >> p->t[2];
}

void WriteState(const Problem& pr, const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "w");
  std::fprintf(f, "%zu %zu %zu\n", pr.kf.size(), pr.cam.size(), pr.points.size());
  auto pose = [&](const Pose& p) {
    std::fprintf(f, "%.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", p.q[0], p.q[1], p.q[2],
                 p.q[3], p.t[0], p.t[1], p.t[2]);
  };
  for (const auto& p : pr.kf) pose(p);
  for (const auto& p : pr.cam) pose(p);
  pose(pr.tfm);
  for (const auto& x : pr.points) std::fprintf(f, "%.17g %.17g %.17g\n", x[0], x[1], x[2]);
  std::fclose(f);
}

void AddPose(ceres::Problem* cp, Pose* p) {
  cp->AddParameterBlock(p->q, 4, new ceres::QuaternionManifold());
  cp->AddParameterBlock(p->t, 3);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: infra_ba_ceres <problem.txt> <state_out.txt> [threads]\n";
    return 2;
  }
  const int threads = argc > 3 ? std::atoi(argv[3]) : 2;
  const auto t0 = std::chrono::steady_clock::now();
  std::ifstream in(argv[1]);
  if (!in) {
    std::cerr << argv[1] << ": cannot read\n";
    return 2;
  }
  Problem pr;
  size_t nk, np, nc;
  in >> nk >> np >> nc >> pr.nvo >> pr.nmk >> pr.nblob;
  pr.f = ReadLens(in);
  for (size_t c = 0; c < nc; ++c) pr.cams.push_back(ReadLens(in));
  for (auto& c : pr.corners) in >> c[0] >> c[1] >> c[2];
  size_t sk, sc, sp;
  in >> sk >> sc >> sp;
  pr.kf.resize(sk);
  pr.cam.resize(sc);
  pr.points.resize(sp);
  for (auto& p : pr.kf) ReadPose(in, &p);
  for (auto& p : pr.cam) ReadPose(in, &p);
  ReadPose(in, &pr.tfm);
  for (auto& x : pr.points) in >> x[0] >> x[1] >> x[2];

  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem cp(po);
  ceres::CauchyLoss loss(3.0);
  for (auto& p : pr.kf) AddPose(&cp, &p);
  for (auto& p : pr.cam) AddPose(&cp, &p);
  AddPose(&cp, &pr.tfm);
  auto* ordering = new ceres::ParameterBlockOrdering;
  for (auto& x : pr.points) {
    cp.AddParameterBlock(x.data(), 3);
    ordering->AddElementToGroup(x.data(), 0);
  }
  auto group1 = [&](Pose& p) {
    ordering->AddElementToGroup(p.q, 1);
    ordering->AddElementToGroup(p.t, 1);
  };
  for (auto& p : pr.kf) group1(p);
  for (auto& p : pr.cam) group1(p);
  group1(pr.tfm);
  for (int o = 0; o < pr.nvo; ++o) {
    int k, j;
    double u, v;
    in >> k >> j >> u >> v;
    auto* cost = new ceres::AutoDiffCostFunction<PointCost, 2, 4, 3, 3>(
        new PointCost{&pr.f, u, v, 1.0 / 0.5});
    cp.AddResidualBlock(cost, &loss, pr.kf[k].q, pr.kf[k].t, pr.points[j].data());
  }
  for (int m = 0; m < pr.nmk; ++m) {
    int c, i, j;
    double alpha, uv[8];
    in >> c >> i >> j >> alpha;
    for (double& x : uv) in >> x;
    for (int k = 0; k < 4; ++k) {
      auto* f = new CornerCost{&pr.cams[c], {pr.corners[k][0], pr.corners[k][1], pr.corners[k][2]},
                               alpha, uv[2 * k], uv[2 * k + 1]};
      auto* cost = new ceres::AutoDiffCostFunction<CornerCost, 2, 4, 3, 4, 3, 4, 3, 4, 3>(f);
      cp.AddResidualBlock(cost, &loss, pr.kf[i].q, pr.kf[i].t, pr.kf[j].q, pr.kf[j].t, pr.tfm.q,
                          pr.tfm.t, pr.cam[c].q, pr.cam[c].t);
    }
  }
  for (int b = 0; b < pr.nblob; ++b) {
    int k, c;
    double u, v;
    in >> k >> c >> u >> v;
    auto* cost = new ceres::AutoDiffCostFunction<PointCost, 2, 4, 3, 3>(
        new PointCost{&pr.f, u, v, 1.0});
    cp.AddResidualBlock(cost, &loss, pr.kf[k].q, pr.kf[k].t, pr.cam[c].t);
  }
  if (!in) {
    std::cerr << argv[1] << ": ends early or holds a non-number\n";
    return 2;
  }
  cp.SetParameterBlockConstant(pr.kf[0].q);
  cp.SetParameterBlockConstant(pr.kf[0].t);
  const auto t1 = std::chrono::steady_clock::now();

  ceres::Solver::Options opt;
  opt.linear_solver_type = ceres::SPARSE_SCHUR;
  opt.linear_solver_ordering.reset(ordering);
  opt.num_threads = threads;
  opt.max_num_iterations = 50;
  opt.function_tolerance = 1e-7;
  opt.minimizer_progress_to_stdout = true;
  ceres::Solver::Summary summary;
  ceres::Solve(opt, &cp, &summary);
  const auto t2 = std::chrono::steady_clock::now();
  std::cout << summary.FullReport() << "\n";
  WriteState(pr, argv[2]);
  const double read_s = std::chrono::duration<double>(t1 - t0).count();
  const double solve_s = std::chrono::duration<double>(t2 - t1).count();
  std::printf("ceres read %.2f s solve %.2f s iterations %zu initial cost %.6f final cost %.6f"
              " (x2, msreg units: %.6f)\n",
              read_s, solve_s, summary.iterations.size(), summary.initial_cost,
              summary.final_cost, 2.0 * summary.final_cost);
  return 0;
}
