/* o3d_seqcc's MeshLab filter plugin: the two jobs of o3d_seqcc in MeshLab's Filters menu.
 *
 * Copyright (C) the o3d_seqcc authors. This file is part of the MeshLab plugin of o3d_seqcc, which links
 * MeshLab's GPL library (libmeshlab-common): it is free software under the GNU General Public License
 * version 3 (see LICENSE in this folder). The rest of o3d_seqcc is MIT-licensed.
 *
 * The filters' names, descriptions and parameters (with the library's defaults and help texts) are not
 * written here: they come from o3d_seqcc_filters.h, generated at build time by
 * `python -m meshlab_filters.native header` from the Python library (see meshlab_filters/native.py).
 */
#ifndef FILTER_O3D_SEQCC_H
#define FILTER_O3D_SEQCC_H

#include <QJsonArray>
#include <QJsonObject>
#include <QObject>
#include <QStringList>

#include <common/interfaces.h>

class FilterO3dSeqccPlugin : public QObject, public MeshFilterInterface
{
	Q_OBJECT
	MESHLAB_PLUGIN_IID_EXPORTER(MESH_FILTER_INTERFACE_IID)
	Q_INTERFACES(MeshFilterInterface)

public:
	// order of the filters in o3d_seqcc_filters.h
	enum { FP_CORRECT = 0, FP_TEXTURE = 1 };

	FilterO3dSeqccPlugin();

	QString pluginName() const override;
	using MeshFilterInterface::filterName;
	using MeshFilterInterface::filterInfo;
	QString filterName(FilterIDType filter) const override;
	QString filterInfo(FilterIDType filter) const override;
	FilterClass getClass(QAction *a) override;
	FILTER_ARITY filterArity(QAction *a) const override;
	int getPreConditions(QAction *a) const override;
	int postCondition(QAction *a) const override;
	using MeshFilterInterface::initParameterSet;
	void initParameterSet(QAction *a, MeshDocument &md, RichParameterList &par) override;
	bool applyFilter(QAction *a, MeshDocument &md, const RichParameterList &par, vcg::CallBackPos *cb) override;

	/// The o3d-seqcc executable the filters run: $O3D_SEQCC_EXECUTABLE, else the one this plugin was built
	/// with, else o3d-seqcc on PATH; empty if none (then *why says where it looked).
	static QString findExecutable(QString *why);

private:
	QJsonObject spec(FilterIDType id) const;
	QStringList childArguments(const QJsonObject &f, const RichParameterList &par, const QString &project,
	                           const QString &out, QString *command) const;
	QString outputFolder(const MeshDocument &md, const QString &given) const;
	QString meshLabWords(const QJsonObject &f, QString message) const;
	bool fail(const QString &message);

	QJsonArray filters;
};

#endif
