/* The few MeshLab API differences the plugin meets, in one place (GPL-3, see LICENSE in this folder).
 *
 * O3D_SEQCC_MESHLAB_2022 (set by CMakeLists.txt when MESHLAB_SRC has common/plugins/interfaces/filter_plugin.h):
 * the plugin interface of MeshLab 2022.02 and later (FilterPlugin, MeshLab 2025.07 and pymeshlab 2025.7);
 * otherwise the one of MeshLab 2020.09 (MeshFilterInterface, what Debian 12 and Ubuntu 22.04-24.04 ship).
 */
#ifndef O3D_SEQCC_MESHLAB_API_H
#define O3D_SEQCC_MESHLAB_API_H

#include <vector>

#ifdef O3D_SEQCC_MESHLAB_2022
#include <common/plugins/interfaces/filter_plugin.h>
using FilterBase = FilterPlugin;
using RasterImage = RasterPlane;
using FilterAction = const QAction;
#define O3D_SEQCC_FILTER_IID FILTER_PLUGIN_IID
#define O3D_SEQCC_CONST_GETTER const
#else
#include <common/interfaces.h>
using FilterBase = MeshFilterInterface;
using RasterImage = Plane;
using FilterAction = QAction;
#define O3D_SEQCC_FILTER_IID MESH_FILTER_INTERFACE_IID
#define O3D_SEQCC_CONST_GETTER
#endif

namespace mlapi {

/// the document's rasters, in layer order
inline std::vector<RasterModel *> rasters(MeshDocument &md)
{
	std::vector<RasterModel *> out;
#ifdef O3D_SEQCC_MESHLAB_2022
	for (RasterModel &r : md.rasterIterator())
		out.push_back(&r);
#else
	for (RasterModel *r : md.rasterList)
		out.push_back(r);
#endif
	return out;
}

inline int rasterCount(const MeshDocument &md)
{
#ifdef O3D_SEQCC_MESHLAB_2022
	return int(md.rasterNumber());
#else
	return md.rasterList.size();
#endif
}

inline std::vector<QString> rasterLabels(const MeshDocument &md)
{
	std::vector<QString> out;
#ifdef O3D_SEQCC_MESHLAB_2022
	for (const RasterModel &r : md.rasterIterator())
		out.push_back(r.label());
#else
	for (const RasterModel *r : md.rasterList)
		out.push_back(r->label());
#endif
	return out;
}

inline bool visible(const MeshModel &m) { return m.isVisible(); }

inline void setVisible(MeshModel &m, bool v)
{
#ifdef O3D_SEQCC_MESHLAB_2022
	m.setVisible(v);
#else
	m.visible = v;
#endif
}

inline void enable(MeshModel &m, int mask)
{
#ifdef O3D_SEQCC_MESHLAB_2022
	m.enable(mask);
#else
	m.Enable(mask);
#endif
}

inline void deleteMesh(MeshDocument &md, MeshModel *m)
{
#ifdef O3D_SEQCC_MESHLAB_2022
	md.delMesh(m->id());
#else
	md.delMesh(m);
#endif
}

}  // namespace mlapi

#endif
