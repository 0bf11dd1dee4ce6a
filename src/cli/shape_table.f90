!> The `anm shape` geometry table: one row per shape in the columns of NIST's geometry tables
!> (`*-geom.orig.dat`), computed at a chosen expansion order.
!>
!> Columns: Name xlow xhi ylow yhi zlow zhi volume surf._area norm_surf_area Equiv._sph._diam.
!> Itrace Nnn length(mm) width(mm) thick(mm) L/T W/T. Itrace is the trace of the inertia tensor
!> about the centroid over that of the sphere of equal volume; Nnn is the order used.
!>
!> Usage:
!>     call write_geometry_header(output_unit)
!>     call write_geometry_row(output_unit, "file.dat", geom)
module anm_cli_shape_table
   use anm_core_kinds, only: wp
   use anm_geometry_properties, only: shape_geometry_type
   implicit none
   private

   public :: write_geometry_header, write_geometry_row

contains

   !> Header line naming the columns.
   subroutine write_geometry_header(unit)
      !> Output unit.
      integer, intent(in) :: unit
      write (unit, '(a)') "Name xlow xhi ylow yhi zlow zhi volume surf._area norm_surf_area " &
         //"Equiv._sph._diam. Itrace Nnn length(mm) width(mm) thick(mm) L/T W/T"
   end subroutine write_geometry_header

   !> One row of the table.
   subroutine write_geometry_row(unit, name, g)
      !> Output unit.
      integer, intent(in) :: unit
      !> Shape name (first field).
      character(len=*), intent(in) :: name
      !> Geometry of the shape.
      type(shape_geometry_type), intent(in) :: g
      write (unit, '(a,6(1x,f11.5),2(1x,es14.7),3(1x,f9.5),1x,i3,3(1x,f11.5),2(1x,f8.5))') &
         trim(name), g%extent_lo(1), g%extent_hi(1), g%extent_lo(2), g%extent_hi(2), g%extent_lo(3), &
         g%extent_hi(3), g%volume, g%area, g%norm_area, g%equiv_diameter, g%itrace, g%order, &
         g%length, g%width, g%thickness, g%length / g%thickness, g%width / g%thickness
   end subroutine write_geometry_row
end module anm_cli_shape_table
