!> VRML 2.0 (VRML97) output of a model: each distinct surface (a shape at an order, coloured by
!> sieve, or a shell layer) is tessellated once in its body frame and DEF'd; each particle is a
!> Transform (translation, rotation, uniform scale) that USEs it. Files stay small for thousands of
!> particles and open in ParaView, MeshLab, FreeCAD or view3dscene (docs/vrml.md).
!>
!> Usage:
!>     meshes(k) = vrml_mesh_type(shape, tess=16, colour=[0.8,0.6,0.4], transparency=0.0)
!>     call write_vrml("model.wrl", box, meshes, mesh_of, center, rotation, scale, error)
module anm_io_vrml
   use anm_core_kinds, only: wp, pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_sh_expansion, only: sh_expansion_type
   use anm_core_output, only: output_set_type, check_complete
   implicit none
   private

   public :: vrml_mesh_type, write_vrml, write_vrml_file, axis_angle

   !> A surface to draw: a star-shaped expansion (body frame) with its tessellation and look.
   type :: vrml_mesh_type
      !> Surface.
      type(sh_expansion_type) :: shape
      !> Polar divisions (azimuthal ones are twice as many).
      integer :: tess = 16
      !> RGB colour in [0, 1].
      real(wp) :: colour(3) = [0.8_wp, 0.7_wp, 0.5_wp]
      !> Transparency in [0, 1] (shells are drawn translucent).
      real(wp) :: transparency = 0.0_wp
   end type vrml_mesh_type


contains

   !> Axis and angle of a rotation matrix (for VRML's Transform.rotation).
   pure subroutine axis_angle(rot, axis, angle)
      !> Rotation matrix.
      real(wp), intent(in) :: rot(3, 3)
      !> Unit axis.
      real(wp), intent(out) :: axis(3)
      !> Angle (radians, 0..pi).
      real(wp), intent(out) :: angle
      real(wp) :: c, v(3), n
      c = max(-1.0_wp, min(1.0_wp, 0.5_wp * (rot(1, 1) + rot(2, 2) + rot(3, 3) - 1.0_wp)))
      angle = acos(c)
      v = [rot(3, 2) - rot(2, 3), rot(1, 3) - rot(3, 1), rot(2, 1) - rot(1, 2)]
      n = norm2(v)
      if (n > 1.0e-8_wp) then
         axis = v / n
      else if (c > 0.0_wp) then
         axis = [0.0_wp, 0.0_wp, 1.0_wp]
         angle = 0.0_wp
      else
         ! angle = pi: axis from the diagonal of (R + I) / 2 = a a^T
         axis = sqrt(max(0.0_wp, 0.5_wp * ([rot(1, 1), rot(2, 2), rot(3, 3)] + 1.0_wp)))
         if (rot(1, 2) + rot(2, 1) < 0.0_wp .and. axis(1) > 0.0_wp) axis(2) = -axis(2)
         if (rot(1, 3) + rot(3, 1) < 0.0_wp .and. axis(1) > 0.0_wp) axis(3) = -axis(3)
         if (axis(1) == 0.0_wp .and. rot(2, 3) + rot(3, 2) < 0.0_wp) axis(3) = -axis(3)
         axis = axis / norm2(axis)
      end if
   end subroutine axis_angle

   !> Write the VRML file safely: to a temporary name in the same folder, then renamed (on error the
   !> temporary is removed and an earlier file is kept). Instance i draws mesh mesh_of(i) at
   !> world = center(:, i) + scale(i) * rotation(:, :, i) body.
   subroutine write_vrml(path, box, meshes, mesh_of, center, rotation, scale, error)
      !> Output file.
      character(len=*), intent(in) :: path
      !> Box edges (mm), drawn as a wireframe.
      real(wp), intent(in) :: box(3)
      !> Distinct surfaces.
      type(vrml_mesh_type), intent(in) :: meshes(:)
      !> Mesh of each instance.
      integer, intent(in) :: mesh_of(:)
      !> Instance centres (3, n).
      real(wp), intent(in) :: center(:, :)
      !> Instance rotations (3, 3, n).
      real(wp), intent(in) :: rotation(:, :, :)
      !> Instance scales.
      real(wp), intent(in) :: scale(:)
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      type(output_set_type) :: set
      character(len=:), allocatable :: tmp
      call set%add(path, tmp)
      call write_vrml_file(tmp, box, meshes, mesh_of, center, rotation, scale, error, shown=path)
      if (allocated(error)) then
         call set%discard()
         return
      end if
      call set%commit(error)
   end subroutine write_vrml

   !> Write the VRML file `path` directly (the caller chooses a temporary name: see write_vrml).
   !> Every write and the close are checked; an error names `shown` (default: path).
   subroutine write_vrml_file(path, box, meshes, mesh_of, center, rotation, scale, error, shown)
      !> Output file.
      character(len=*), intent(in) :: path
      !> Box edges (mm), drawn as a wireframe.
      real(wp), intent(in) :: box(3)
      !> Distinct surfaces.
      type(vrml_mesh_type), intent(in) :: meshes(:)
      !> Mesh of each instance.
      integer, intent(in) :: mesh_of(:)
      !> Instance centres (3, n).
      real(wp), intent(in) :: center(:, :)
      !> Instance rotations (3, 3, n).
      real(wp), intent(in) :: rotation(:, :, :)
      !> Instance scales.
      real(wp), intent(in) :: scale(:)
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      !> Name used in messages (the final name when writing a temporary).
      character(len=*), intent(in), optional :: shown
      integer :: unit, stat, i, k
      logical, allocatable :: defined(:)
      real(wp) :: axis(3), angle
      character(len=512) :: msg
      character(len=:), allocatable :: name

      name = path
      if (present(shown)) name = shown
      open (newunit=unit, file=path, access="stream", form="formatted", status="replace", action="write", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, name//": cannot write VRML file ("//trim(msg)//")", error_code%io)
         return
      end if
      msg = ""
      write (unit, '(a)', iostat=stat, iomsg=msg) "#VRML V2.0 utf8", "# Anm model", "WorldInfo { title ""Anm model"" }"
      if (stat == 0) write (unit, '(a,3(f0.4,1x),a)', iostat=stat, iomsg=msg) "Viewpoint { position ", &
         0.5_wp * box(1), 0.5_wp * box(2), 2.5_wp * box(3), " description ""front"" }"
      if (stat == 0) call write_box(unit, box, stat)
      allocate (defined(size(meshes)))
      defined = .false.
      do i = 1, size(mesh_of)
         if (stat /= 0) exit
         k = mesh_of(i)
         call axis_angle(rotation(:, :, i), axis, angle)
         write (unit, '(a,3(es14.7,1x),a,4(es14.7,1x),a,3(es14.7,1x),a)', iostat=stat, iomsg=msg) &
            "Transform { translation ", center(:, i), " rotation ", axis, angle, " scale ", scale(i), scale(i), &
            scale(i), " children ["
         if (stat /= 0) exit
         if (defined(k)) then
            write (unit, '(a,i0,a)', iostat=stat, iomsg=msg) "  USE M", k, " ] }"
         else
            call write_mesh(unit, k, meshes(k), stat)
            if (stat == 0) write (unit, '(a)', iostat=stat, iomsg=msg) " ] }"
            defined(k) = .true.
         end if
      end do
      if (stat /= 0) then
         close (unit, iostat=i)
         call fatal_error(error, name//": writing the VRML file failed ("//trim(io_reason(stat, msg))//")", &
                          error_code%io)
         return
      end if
      call check_complete(unit, path, name, error)
      if (allocated(error)) then
         close (unit, iostat=i)
         return
      end if
      close (unit, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, name//": error closing the VRML file ("//trim(msg)//")", error_code%io)
         return
      end if
   end subroutine write_vrml_file

   !> Reason of a failed write: the runtime's message, or the status when it gave none.
   function io_reason(stat, msg) result(reason)
      integer, intent(in) :: stat
      character(len=*), intent(in) :: msg
      character(len=:), allocatable :: reason
      character(len=16) :: num
      if (len_trim(msg) > 0) then
         reason = trim(msg)
      else
         write (num, '(i0)') stat
         reason = "I/O status "//trim(num)
      end if
   end function io_reason

   subroutine write_box(unit, box, stat)
      integer, intent(in) :: unit
      real(wp), intent(in) :: box(3)
      integer, intent(out) :: stat
      integer :: i, ios
      real(wp) :: v(3, 8)
      stat = 0
      do i = 0, 7
         v(:, i + 1) = [merge(box(1), 0.0_wp, btest(i, 0)), merge(box(2), 0.0_wp, btest(i, 1)), &
                        merge(box(3), 0.0_wp, btest(i, 2))]
      end do
      write (unit, '(a)', iostat=ios) &
         "Shape { appearance Appearance { material Material { emissiveColor 0.2 0.2 0.2 } }", &
         " geometry IndexedLineSet { coord Coordinate { point ["
      if (ios /= 0) stat = ios
      do i = 1, 8
         write (unit, '(3(f0.4,1x),a)', iostat=ios) v(:, i), ","
         if (ios /= 0) stat = ios
      end do
      write (unit, '(a)', iostat=ios) "] } coordIndex [ 0 1 3 2 0 -1 4 5 7 6 4 -1 0 4 -1 1 5 -1 2 6 -1 3 7 -1 ] } }"
      if (ios /= 0) stat = ios
   end subroutine write_box

   !> DEF'd Shape of one mesh: a latitude-longitude tessellation with the two poles.
   subroutine write_mesh(unit, k, mesh, stat)
      integer, intent(in) :: unit, k
      type(vrml_mesh_type), intent(in) :: mesh
      integer, intent(out) :: stat
      integer :: nt, np, i, j, a, b, c, d, north, south, ios
      real(wp) :: th, ph, u(3)
      stat = 0
      nt = max(4, mesh%tess)
      np = 2 * nt
      write (unit, '(a,i0,a)', iostat=ios) "  DEF M", k, " Shape { appearance Appearance { material Material {"
      if (ios /= 0) stat = ios
      write (unit, '(a,3(f0.4,1x),a,f0.3,a)', iostat=ios) "    diffuseColor ", mesh%colour, " transparency ", &
         mesh%transparency, " } }"
      if (ios /= 0) stat = ios
      write (unit, '(a)', iostat=ios) &
         "    geometry IndexedFaceSet { creaseAngle 1.0 solid FALSE coord Coordinate { point ["
      if (ios /= 0) stat = ios
      ! vertices: rings i = 1..nt-1 (theta = pi i / nt), then the poles
      do i = 1, nt - 1
         th = pi * i / real(nt, wp)
         do j = 0, np - 1
            ph = 2.0_wp * pi * j / real(np, wp)
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            write (unit, '(3(es13.6,1x),a)', iostat=ios) mesh%shape%radius_dir(u) * u, ","
            if (ios /= 0) stat = ios
         end do
      end do
      write (unit, '(3(es13.6,1x),a)', iostat=ios) mesh%shape%radius_dir([0.0_wp, 0.0_wp, 1.0_wp]) * &
         [0.0_wp, 0.0_wp, 1.0_wp], ","
      if (ios /= 0) stat = ios
      write (unit, '(3(es13.6,1x),a)', iostat=ios) mesh%shape%radius_dir([0.0_wp, 0.0_wp, -1.0_wp]) * &
         [0.0_wp, 0.0_wp, -1.0_wp], ","
      if (ios /= 0) stat = ios
      write (unit, '(a)', iostat=ios) "    ] } coordIndex ["
      if (ios /= 0) stat = ios
      north = (nt - 1) * np
      south = north + 1
      do j = 0, np - 1
         write (unit, '(3(i0,1x),a)', iostat=ios) north, mod(j + 1, np), j, "-1"
         if (ios /= 0) stat = ios
      end do
      do i = 0, nt - 3
         do j = 0, np - 1
            a = i * np + j
            b = i * np + mod(j + 1, np)
            c = (i + 1) * np + mod(j + 1, np)
            d = (i + 1) * np + j
            write (unit, '(4(i0,1x),a)', iostat=ios) a, b, c, d, "-1"
            if (ios /= 0) stat = ios
         end do
      end do
      do j = 0, np - 1
         write (unit, '(3(i0,1x),a)', iostat=ios) (nt - 2) * np + j, (nt - 2) * np + mod(j + 1, np), south, "-1"
         if (ios /= 0) stat = ios
      end do
      write (unit, '(a)', iostat=ios) "    ] } }"
      if (ios /= 0) stat = ios
   end subroutine write_mesh
end module anm_io_vrml
