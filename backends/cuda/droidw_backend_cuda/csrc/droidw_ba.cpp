// Python binding of the droidw CUDA kernels: settings are passed as named structs,
// never as long positional argument lists.
#include "droidw_ba.h"

namespace py = pybind11;

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.doc() = "droidw uncertainty-aware dense BA kernels";
  py::class_<droidw::LinearizeConfig>(m, "LinearizeConfig")
      .def(py::init<>())
      .def_readwrite("fx", &droidw::LinearizeConfig::fx)
      .def_readwrite("fy", &droidw::LinearizeConfig::fy)
      .def_readwrite("cx", &droidw::LinearizeConfig::cx)
      .def_readwrite("cy", &droidw::LinearizeConfig::cy)
      .def_readwrite("min_depth", &droidw::LinearizeConfig::min_depth)
      .def_readwrite("flow_weight_scale", &droidw::LinearizeConfig::flow_weight_scale)
      .def_readwrite("uncertainty_mode", &droidw::LinearizeConfig::uncertainty_mode)
      .def_readwrite("bidirectional", &droidw::LinearizeConfig::bidirectional)
      .def_readwrite("focal_mode", &droidw::LinearizeConfig::focal_mode)
      .def_readwrite("with_depth", &droidw::LinearizeConfig::with_depth);
  py::class_<droidw::SimilarityConfig>(m, "SimilarityConfig")
      .def(py::init<>())
      .def_readwrite("fx", &droidw::SimilarityConfig::fx)
      .def_readwrite("fy", &droidw::SimilarityConfig::fy)
      .def_readwrite("cx", &droidw::SimilarityConfig::cx)
      .def_readwrite("cy", &droidw::SimilarityConfig::cy)
      .def_readwrite("min_depth", &droidw::SimilarityConfig::min_depth)
      .def_readwrite("gamma_data", &droidw::SimilarityConfig::gamma_data)
      .def_readwrite("sim_threshold", &droidw::SimilarityConfig::sim_threshold)
      .def_readwrite("geo_sigma", &droidw::SimilarityConfig::geo_sigma);
  py::class_<droidw::LinearizeInputs>(m, "LinearizeInputs")
      .def(py::init<>())
      .def_readwrite("rel", &droidw::LinearizeInputs::rel)
      .def_readwrite("disps", &droidw::LinearizeInputs::disps)
      .def_readwrite("ii", &droidw::LinearizeInputs::ii)
      .def_readwrite("jj", &droidw::LinearizeInputs::jj)
      .def_readwrite("target", &droidw::LinearizeInputs::target)
      .def_readwrite("weight", &droidw::LinearizeInputs::weight)
      .def_readwrite("umap", &droidw::LinearizeInputs::umap);
  py::class_<droidw::SimilarityInputs>(m, "SimilarityInputs")
      .def(py::init<>())
      .def_readwrite("rel", &droidw::SimilarityInputs::rel)
      .def_readwrite("disps", &droidw::SimilarityInputs::disps)
      .def_readwrite("ii", &droidw::SimilarityInputs::ii)
      .def_readwrite("jj", &droidw::SimilarityInputs::jj)
      .def_readwrite("omega", &droidw::SimilarityInputs::omega)
      .def_readwrite("features", &droidw::SimilarityInputs::features)
      .def_readwrite("u", &droidw::SimilarityInputs::u)
      .def_readwrite("target", &droidw::SimilarityInputs::target);
  m.attr("CLAMP_SLOPE") = droidw::kClampSlope;
  m.attr("CLAMP_OFFSET") = droidw::kClampOffset;
  m.attr("CLAMP_FLOOR") = droidw::kClampFloor;
  m.def("linearize", &droidw::linearize_cuda, "GN linearisation: per-edge Hessian blocks and E rows",
        py::arg("config"), py::arg("inputs"));
  m.def("similarity", &droidw::similarity_cuda, "uncertainty data term and its d/du map",
        py::arg("config"), py::arg("inputs"));
}
