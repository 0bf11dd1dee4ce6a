!> VRML 2.0 (VRML97) output of a model: the box as a wireframe and every instance (a particle coloured
!> by sieve, or a shell layer) as a tessellated surface. Two layouts (docs/vrml.md):
!>
!> - `vrml_layout%instanced` (default): each distinct surface (a shape at an order, or a shell layer)
!>   is tessellated once in its body frame and DEF'd; each instance is a Transform (translation,
!>   rotation, uniform scale) that USEs it. Small files; VTK imports it in time quadratic in the
!>   instances.
!> - `vrml_layout%flat`: every instance placed in world coordinates, all instances of one look (a
!>   sieve's colour, a shell layer's colour and transparency) in one Shape with one IndexedFaceSet.
!>   VTK/ParaView import it in linear time; files are about 30 times larger.
!>
!> Every number is written with a leading zero (0.55, not .55: VTK reads .55 as 0). Every write is
!> checked; the file is written to a temporary name and renamed (write_vrml), or to a name the
!> caller chooses (write_vrml_file, with the final name for messages).
!>
!> Usage:
!>     meshes(k) = vrml_mesh_type(shape, tess=16, colour=[0.8,0.6,0.4], transparency=0.0)
!>     call write_vrml("model.wrl", box, meshes, mesh_of, center, rotation, scale, error, &
!>                     layout=vrml_layout%flat)
module anm_io_vrml
   use anm_core_kinds, only: wp, pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_sh_expansion, only: sh_expansion_type
   use anm_core_output, only: output_set_type, check_complete
   implicit none
   private

   public :: vrml_mesh_type, write_vrml, write_vrml_file, axis_angle, vrml_layout, vrml_layout_name

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

   !> VRML file layouts.
   type :: vrml_layout_enum
      !> One DEF'd mesh per surface, one Transform + USE per instance: small files.
      integer :: instanced = 1
      !> One IndexedFaceSet per look with world-space vertices: VTK imports it in linear time.
      integer :: flat = 2
   end type vrml_layout_enum

   !> The layouts, used as `vrml_layout%flat`.
   type(vrml_layout_enum), parameter :: vrml_layout = vrml_layout_enum()

   !> Vertices of one tessellated surface in its body frame (3, nvert).
   type :: body_mesh_type
      !> Vertices (3, nvert), shape units.
      real(wp), allocatable :: v(:, :)
   end type body_mesh_type

contains

   !> Namelist spelling of a layout ('instanced' or 'flat').
   pure function vrml_layout_name(layout) result(s)
      !> One of `vrml_layout`.
      integer, intent(in) :: layout
      character(len=:), allocatable :: s
      if (layout == vrml_layout%flat) then
         s = "flat"
      else
         s = "instanced"
      end if
   end function vrml_layout_name

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
   subroutine write_vrml(path, box, meshes, mesh_of, center, rotation, scale, error, layout)
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
      !> One of `vrml_layout` (default: instanced).
      integer, intent(in), optional :: layout
      type(output_set_type) :: set
      character(len=:), allocatable :: tmp
      call set%add(path, tmp)
      call write_vrml_file(tmp, box, meshes, mesh_of, center, rotation, scale, error, shown=path, layout=layout)
      if (allocated(error)) then
         call set%discard()
         return
      end if
      call set%commit(error)
   end subroutine write_vrml

   !> Write the VRML file `path` directly (the caller chooses a temporary name: see write_vrml).
   !> Every write and the close are checked; an error names `shown` (default: path).
   subroutine write_vrml_file(path, box, meshes, mesh_of, center, rotation, scale, error, shown, layout)
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
      !> One of `vrml_layout` (default: instanced).
      integer, intent(in), optional :: layout
      integer :: unit, stat, ios, mode
      character(len=512) :: msg
      character(len=:), allocatable :: name

      name = path
      if (present(shown)) name = shown
      mode = vrml_layout%instanced
      if (present(layout)) mode = layout
      open (newunit=unit, file=path, access="stream", form="formatted", status="replace", action="write", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, name//": cannot write VRML file ("//trim(msg)//")", error_code%io)
         return
      end if
      msg = ""
      write (unit, '(a)', iostat=stat, iomsg=msg) "#VRML V2.0 utf8", "# Anm model ("//vrml_layout_name(mode)// &
         " layout)", "WorldInfo { title ""Anm model"" }"
      if (stat == 0) write (unit, '(a,3(es13.6,1x),a)', iostat=stat, iomsg=msg) "Viewpoint { position ", &
         0.5_wp * box(1), 0.5_wp * box(2), 2.5_wp * box(3), " description ""front"" }"
      if (stat == 0) call write_box(unit, box, stat, msg)
      if (stat == 0) then
         if (mode == vrml_layout%flat) then
            call write_groups(unit, box, meshes, mesh_of, center, rotation, scale, stat, msg)
         else
            call write_instances(unit, meshes, mesh_of, center, rotation, scale, stat, msg)
         end if
      end if
      if (stat /= 0) then
         close (unit, iostat=ios)
         call fatal_error(error, name//": writing the VRML file failed ("//trim(io_reason(stat, msg))//")", &
                          error_code%io)
         return
      end if
      call check_complete(unit, path, name, error)
      if (allocated(error)) then
         close (unit, iostat=ios)
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

   !> The box as a grey wireframe.
   subroutine write_box(unit, box, stat, msg)
      integer, intent(in) :: unit
      real(wp), intent(in) :: box(3)
      integer, intent(out) :: stat
      character(len=*), intent(inout) :: msg
      integer :: i
      real(wp) :: v(3, 8)
      do i = 0, 7
         v(:, i + 1) = [merge(box(1), 0.0_wp, btest(i, 0)), merge(box(2), 0.0_wp, btest(i, 1)), &
                        merge(box(3), 0.0_wp, btest(i, 2))]
      end do
      write (unit, '(a)', iostat=stat, iomsg=msg) &
         "Shape { appearance Appearance { material Material { emissiveColor 0.2 0.2 0.2 } }", &
         " geometry IndexedLineSet { coord Coordinate { point ["
      if (stat /= 0) return
      write (unit, '(3(es13.6,1x),",")', iostat=stat, iomsg=msg) v
      if (stat /= 0) return
      write (unit, '(a)', iostat=stat, iomsg=msg) &
         "] } coordIndex [ 0 1 3 2 0 -1 4 5 7 6 4 -1 0 4 -1 1 5 -1 2 6 -1 3 7 -1 ] } }"
   end subroutine write_box

   !> Instanced layout: one Transform per instance; the first instance of a mesh DEFs it (body
   !> frame), later ones USE it.
   subroutine write_instances(unit, meshes, mesh_of, center, rotation, scale, stat, msg)
      integer, intent(in) :: unit
      type(vrml_mesh_type), intent(in) :: meshes(:)
      integer, intent(in) :: mesh_of(:)
      real(wp), intent(in) :: center(:, :), rotation(:, :, :), scale(:)
      integer, intent(out) :: stat
      character(len=*), intent(inout) :: msg
      logical :: defined(size(meshes))
      real(wp) :: axis(3), angle
      integer :: i, k
      stat = 0
      defined = .false.
      do i = 1, size(mesh_of)
         k = mesh_of(i)
         call axis_angle(rotation(:, :, i), axis, angle)
         write (unit, '(a,3(es14.7,1x),a,4(es14.7,1x),a,3(es14.7,1x),a)', iostat=stat, iomsg=msg) &
            "Transform { translation ", center(:, i), " rotation ", axis, angle, " scale ", scale(i), scale(i), &
            scale(i), " children ["
         if (stat /= 0) return
         if (defined(k)) then
            write (unit, '(a,i0,a)', iostat=stat, iomsg=msg) "  USE M", k, " ] }"
         else
            call write_mesh(unit, k, meshes(k), stat, msg)
            if (stat /= 0) return
            write (unit, '(a)', iostat=stat, iomsg=msg) " ] }"
            defined(k) = .true.
         end if
         if (stat /= 0) return
      end do
   end subroutine write_instances

   !> DEF'd Shape of one mesh in its body frame.
   subroutine write_mesh(unit, k, mesh, stat, msg)
      integer, intent(in) :: unit, k
      type(vrml_mesh_type), intent(in) :: mesh
      integer, intent(out) :: stat
      character(len=*), intent(inout) :: msg
      real(wp), allocatable :: v(:, :)
      write (unit, '(a,i0,a)', iostat=stat, iomsg=msg) "  DEF M", k, " Shape { appearance Appearance { material Material {"
      if (stat /= 0) return
      write (unit, '(a,3(f6.4,1x),a,f5.3,a)', iostat=stat, iomsg=msg) "    diffuseColor ", mesh%colour, &
         "transparency ", mesh%transparency, " } }"
      if (stat /= 0) return
      write (unit, '(a)', iostat=stat, iomsg=msg) &
         "    geometry IndexedFaceSet { creaseAngle 1.0 solid FALSE coord Coordinate { point ["
      if (stat /= 0) return
      call body_vertices(mesh, v)
      write (unit, '(3(es13.6,1x),",")', iostat=stat, iomsg=msg) v
      if (stat /= 0) return
      write (unit, '(a)', iostat=stat, iomsg=msg) "    ] } coordIndex ["
      if (stat /= 0) return
      call write_faces(unit, max(4, mesh%tess), 0, stat, msg)
      if (stat /= 0) return
      write (unit, '(a)', iostat=stat, iomsg=msg) "    ] } }"
   end subroutine write_mesh

   !> Flat layout: one Shape per look (colour and transparency: a sieve's particles, or a shell
   !> layer), its IndexedFaceSet holding every instance of that look with vertices in world
   !> coordinates. VTK's importer reads this in time linear in the instances (docs/vrml.md).
   subroutine write_groups(unit, box, meshes, mesh_of, center, rotation, scale, stat, msg)
      integer, intent(in) :: unit
      real(wp), intent(in) :: box(3)
      type(vrml_mesh_type), intent(in) :: meshes(:)
      integer, intent(in) :: mesh_of(:)
      real(wp), intent(in) :: center(:, :), rotation(:, :, :), scale(:)
      integer, intent(out) :: stat
      character(len=*), intent(inout) :: msg
      type(body_mesh_type), allocatable :: body(:)
      integer, allocatable :: group(:), nvert(:)
      integer :: k, j, g, ngroup, i, off, w, count
      real(wp) :: reach
      character(len=32) :: vfmt

      stat = 0
      allocate (body(size(meshes)), group(size(meshes)), nvert(size(meshes)))
      ngroup = 0
      do k = 1, size(meshes)
         group(k) = 0
         do j = 1, k - 1
            if (all(meshes(j)%colour == meshes(k)%colour) .and. meshes(j)%transparency == meshes(k)%transparency) then
               group(k) = group(j)
               exit
            end if
         end do
         if (group(k) == 0) then
            ngroup = ngroup + 1
            group(k) = ngroup
         end if
         nvert(k) = 0
         if (any(mesh_of == k)) then
            call body_vertices(meshes(k), body(k)%v)
            nvert(k) = size(body(k)%v, 2)
         end if
      end do
      ! fixed width wide enough for every coordinate, so that gfortran writes the leading zero
      reach = maxval(abs(box))
      if (size(mesh_of) > 0) reach = max(reach, maxval(abs(center)) + maxval(abs(scale)) * &
                                          maxval([(vertex_reach(body(k)), k = 1, size(meshes))]))
      w = 6 + max(1, ceiling(log10(max(1.0_wp, reach + 1.0_wp))))
      write (vfmt, '(a,i0,a)') "(3(f", w, ".4,1x),"","")"
      do g = 1, ngroup
         count = 0
         do i = 1, size(mesh_of)
            if (group(mesh_of(i)) == g) count = count + 1
         end do
         if (count == 0) cycle
         k = findloc(group, g, dim=1)
         write (unit, '(a,i0,a)', iostat=stat, iomsg=msg) "# ", count, " surfaces"
         if (stat /= 0) return
         write (unit, '(a,3(f6.4,1x),a,f5.3,a)', iostat=stat, iomsg=msg) &
            "Shape { appearance Appearance { material Material { diffuseColor ", meshes(k)%colour, &
            "transparency ", meshes(k)%transparency, " } }"
         if (stat /= 0) return
         write (unit, '(a)', iostat=stat, iomsg=msg) &
            "  geometry IndexedFaceSet { creaseAngle 1.0 solid FALSE coord Coordinate { point ["
         if (stat /= 0) return
         do i = 1, size(mesh_of)
            k = mesh_of(i)
            if (group(k) /= g) cycle
            write (unit, vfmt, iostat=stat, iomsg=msg) &
               (center(:, i) + scale(i) * matmul(rotation(:, :, i), body(k)%v(:, j)), j = 1, nvert(k))
            if (stat /= 0) return
         end do
         write (unit, '(a)', iostat=stat, iomsg=msg) "  ] } coordIndex ["
         if (stat /= 0) return
         off = 0
         do i = 1, size(mesh_of)
            k = mesh_of(i)
            if (group(k) /= g) cycle
            call write_faces(unit, max(4, meshes(k)%tess), off, stat, msg)
            if (stat /= 0) return
            off = off + nvert(k)
         end do
         write (unit, '(a)', iostat=stat, iomsg=msg) "  ] } }"
         if (stat /= 0) return
      end do
   end subroutine write_groups

   !> Largest vertex distance of a tessellated surface (0 if not tessellated).
   pure function vertex_reach(b) result(r)
      type(body_mesh_type), intent(in) :: b
      real(wp) :: r
      r = 0.0_wp
      if (allocated(b%v)) r = maxval(norm2(b%v, dim=1))
   end function vertex_reach

   !> Body-frame vertices of a mesh: a latitude-longitude tessellation, rings i = 1..nt-1
   !> (theta = pi i / nt, 2 nt points each), then the north and south poles.
   subroutine body_vertices(mesh, v)
      type(vrml_mesh_type), intent(in) :: mesh
      real(wp), allocatable, intent(out) :: v(:, :)
      integer :: nt, np, i, j, n
      real(wp) :: th, ph, u(3)
      nt = max(4, mesh%tess)
      np = 2 * nt
      allocate (v(3, (nt - 1) * np + 2))
      n = 0
      do i = 1, nt - 1
         th = pi * i / real(nt, wp)
         do j = 0, np - 1
            ph = 2.0_wp * pi * j / real(np, wp)
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            n = n + 1
            v(:, n) = mesh%shape%radius_dir(u) * u
         end do
      end do
      v(:, n + 1) = mesh%shape%radius_dir([0.0_wp, 0.0_wp, 1.0_wp]) * [0.0_wp, 0.0_wp, 1.0_wp]
      v(:, n + 2) = mesh%shape%radius_dir([0.0_wp, 0.0_wp, -1.0_wp]) * [0.0_wp, 0.0_wp, -1.0_wp]
   end subroutine body_vertices

   !> Faces of one instance (vertices numbered from off): triangles at the poles, quads between rings.
   subroutine write_faces(unit, nt, off, stat, msg)
      integer, intent(in) :: unit, nt, off
      integer, intent(out) :: stat
      character(len=*), intent(inout) :: msg
      integer :: np, i, j, north, south
      np = 2 * nt
      north = off + (nt - 1) * np
      south = north + 1
      write (unit, '(3(i0,1x),"-1")', iostat=stat, iomsg=msg) (north, off + mod(j + 1, np), off + j, j = 0, np - 1)
      if (stat /= 0) return
      write (unit, '(4(i0,1x),"-1")', iostat=stat, iomsg=msg) ((off + i * np + j, off + i * np + mod(j + 1, np), &
                                                                off + (i + 1) * np + mod(j + 1, np), off + (i + 1) * np + j, &
                                                                j = 0, np - 1), i = 0, nt - 3)
      if (stat /= 0) return
      write (unit, '(3(i0,1x),"-1")', iostat=stat, iomsg=msg) (off + (nt - 2) * np + j, off + (nt - 2) * np + mod(j + 1, np), &
                                                               south, j = 0, np - 1)
   end subroutine write_faces
end module anm_io_vrml
