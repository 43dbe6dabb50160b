// Python binding of the droidw native CPU kernels: settings are passed as named structs,
// never as long positional argument lists.
#include <torch/extension.h>

#include "native_ba.h"

namespace py = pybind11;
using droidw::native::SimilarityConfig;
using droidw::native::SimilarityInputs;
using droidw::native::StepConfig;
using droidw::native::StepInputs;

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.doc() = "droidw uncertainty-aware dense BA: native CPU kernels";
  py::class_<StepConfig>(m, "StepConfig")
      .def(py::init<>())
      .def_readwrite("fx", &StepConfig::fx)
      .def_readwrite("fy", &StepConfig::fy)
      .def_readwrite("cx", &StepConfig::cx)
      .def_readwrite("cy", &StepConfig::cy)
      .def_readwrite("min_depth", &StepConfig::min_depth)
      .def_readwrite("flow_weight_scale", &StepConfig::flow_weight_scale)
      .def_readwrite("uncertainty_mode", &StepConfig::uncertainty_mode)
      .def_readwrite("bidirectional", &StepConfig::bidirectional)
      .def_readwrite("focal_mode", &StepConfig::focal_mode)
      .def_readwrite("motion_only", &StepConfig::motion_only)
      .def_readwrite("gamma_depth", &StepConfig::gamma_depth)
      .def_readwrite("depth_damping", &StepConfig::depth_damping)
      .def_readwrite("prior_damping", &StepConfig::prior_damping)
      .def_readwrite("pose_damping_rel", &StepConfig::pose_damping_rel)
      .def_readwrite("pose_damping_abs", &StepConfig::pose_damping_abs)
      .def_readwrite("min_disp", &StepConfig::min_disp);
  py::class_<StepInputs>(m, "StepInputs")
      .def(py::init<>())
      .def_readwrite("rel", &StepInputs::rel)
      .def_readwrite("disps", &StepInputs::disps)
      .def_readwrite("ii", &StepInputs::ii)
      .def_readwrite("jj", &StepInputs::jj)
      .def_readwrite("target", &StepInputs::target)
      .def_readwrite("weight", &StepInputs::weight)
      .def_readwrite("umap", &StepInputs::umap)
      .def_readwrite("prior", &StepInputs::prior)
      .def_readwrite("slot", &StepInputs::slot);
  py::class_<SimilarityConfig>(m, "SimilarityConfig")
      .def(py::init<>())
      .def_readwrite("fx", &SimilarityConfig::fx)
      .def_readwrite("fy", &SimilarityConfig::fy)
      .def_readwrite("cx", &SimilarityConfig::cx)
      .def_readwrite("cy", &SimilarityConfig::cy)
      .def_readwrite("min_depth", &SimilarityConfig::min_depth)
      .def_readwrite("gamma_data", &SimilarityConfig::gamma_data)
      .def_readwrite("sim_threshold", &SimilarityConfig::sim_threshold)
      .def_readwrite("geo_sigma", &SimilarityConfig::geo_sigma);
  py::class_<SimilarityInputs>(m, "SimilarityInputs")
      .def(py::init<>())
      .def_readwrite("rel", &SimilarityInputs::rel)
      .def_readwrite("disps", &SimilarityInputs::disps)
      .def_readwrite("ii", &SimilarityInputs::ii)
      .def_readwrite("jj", &SimilarityInputs::jj)
      .def_readwrite("omega", &SimilarityInputs::omega)
      .def_readwrite("features", &SimilarityInputs::features)
      .def_readwrite("norms", &SimilarityInputs::norms)
      .def_readwrite("u", &SimilarityInputs::u)
      .def_readwrite("target", &SimilarityInputs::target);
  m.attr("CLAMP_SLOPE") = droidw::kClampSlope;
  m.attr("CLAMP_OFFSET") = droidw::kClampOffset;
  m.attr("CLAMP_FLOOR") = droidw::kClampFloor;
  m.def("ba_step", &droidw::native::ba_step, "one Gauss-Newton step: node updates, new disparities, cost, solved",
        py::arg("config"), py::arg("inputs"));
  m.def("similarity", &droidw::native::similarity, "uncertainty data term and its d/du map",
        py::arg("config"), py::arg("inputs"));
  m.def("reproject", &droidw::native::reproject, "rigid reprojection (Eq. 1): coords and validity",
        py::arg("rel"), py::arg("disps"), py::arg("intrinsics"), py::arg("ii"), py::arg("min_depth"));
}
