!> Parameter studies of the EOB method written as CSV (thesis section 2.5.1): the extent-box
!> volume V_box versus N_ext for one particle (Fig 2.14) and D_overlap versus N_box for two barely
!> overlapping copies of a particle (Fig 2.15).
!>
!> N_box can be read two ways. Ours (`nbox_range%polar`, the engine's): scan directions on a fixed
!> grid of spacing pi/N_box in theta and phi over the whole sphere, restricted to the patches that
!> may meet the EOB. The thesis' (section 2.2, Fig 2.7, `nbox_range%eob`): the minimum and maximum
!> theta and phi of the particle's surface inside the EOB are found, and N_box points are scanned
!> along each of these two ranges (N_box^2 directions per body, both ends included), so the spacing
!> shrinks with the EOB. The range is found on a 1-degree grid widened by one grid step; a phi reading
!> that wraps through 0 becomes the whole [0, 2 pi) (min and max of phi, as the thesis describes).
!>
!> Usage:
!>     call study_next(shape, 14, "vbox.csv", error)
!>     call study_nbox(shape, 14, 2024, "doverlap.csv", error)
!>     call study_nbox(shape, 14, 2024, "doverlap.csv", error, nbox_range%eob)
module anm_contact_studies
   use anm_core_kinds, only: wp, i8, pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_output, only: write_text_file
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type
   use anm_geometry_extent, only: extent_scan
   use anm_geometry_rotation, only: random_rotation
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_contact_overlap, only: overlap_depth
   implicit none
   private

   public :: study_next, study_nbox, nbox_range, thesis_overlap_depth

   !> How N_box samples the directions of the surface scan.
   type :: nbox_range_enum
      !> Fixed spacing pi/N_box over the full polar and azimuthal range (ours, the engine's).
      integer :: polar = 1
      !> N_box points over the angular range of the surface inside the EOB (the thesis).
      integer :: eob = 2
   end type nbox_range_enum

   !> The N_box readings, used as `nbox_range%eob`.
   type(nbox_range_enum), parameter :: nbox_range = nbox_range_enum()

   !> Grid (per degree) that finds the angular range of the surface inside the EOB.
   integer, parameter :: range_rows = 180

contains

   !> Write `next,v_box` for N_ext = 4..160 (thesis extent scan, shape units cubed).
   subroutine study_next(shape, nused, path, error)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Order used (negative: all coefficients).
      integer, intent(in) :: nused
      !> Output CSV file.
      character(len=*), intent(in) :: path
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: body
      integer :: next
      character(len=80) :: line
      character(len=:), allocatable :: text
      real(wp) :: lo(3), hi(3)
      call build(body, shape, nused, error)
      if (allocated(error)) return
      text = "next,v_box,v_box_certified"//new_line("a")
      do next = 4, 160, 2
         call extent_scan(body%shape, next, lo, hi)
         write (line, '(i0,2(",",es16.9))') next, product(hi - lo), product(body%box_hi - body%box_lo)
         text = text//trim(line)//new_line("a")
      end do
      call write_text_file(path, text, error)
   end subroutine study_next

   !> Write `nbox,d_overlap` for N_box = 10..300 for two copies of the particle (random
   !> rotations from `seed`) placed along x at 0.998 times their contact distance (found by
   !> bisection on D_overlap at N_box = 1024, ours); D_overlap in shape units, N_box read as `range`
   !> (one of `nbox_range`, default `nbox_range%polar`).
   subroutine study_nbox(shape, nused, seed, path, error, reading)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Order used (negative: all coefficients).
      integer, intent(in) :: nused
      !> Seed of the two rotations.
      integer, intent(in) :: seed
      !> Output CSV file.
      character(len=*), intent(in) :: path
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      !> Reading of N_box, one of `nbox_range`.
      integer, intent(in), optional :: reading
      type(contact_body_type) :: body
      type(rng_type) :: rng
      real(wp) :: d
      logical :: thesis
      real(wp) :: rota(3, 3), rotb(3, 3), lo, hi, mid, zero(3), ex(3)
      integer :: nbox, it
      character(len=80) :: line
      character(len=:), allocatable :: text
      call build(body, shape, nused, error)
      if (allocated(error)) return
      call new_rng(rng, int(seed, i8), 1_i8)
      rota = random_rotation(rng)
      rotb = random_rotation(rng)
      zero = 0.0_wp
      ex = [1.0_wp, 0.0_wp, 0.0_wp]
      lo = 2.0_wp * body%r_min
      hi = 2.0_wp * body%r_max
      do it = 1, 40
         mid = 0.5_wp * (lo + hi)
         if (overlap_depth(body, zero, rota, 1.0_wp, body, mid * ex, rotb, 1.0_wp, 1024) > 0.0_wp) then
            lo = mid
         else
            hi = mid
         end if
      end do
      thesis = .false.
      if (present(reading)) thesis = reading == nbox_range%eob
      text = "nbox,d_overlap"//new_line("a")
      do nbox = 10, 300, 10
         if (thesis) then
            d = thesis_overlap_depth(body, zero, rota, body, 0.998_wp * lo * ex, rotb, nbox)
         else
            d = overlap_depth(body, zero, rota, 1.0_wp, body, 0.998_wp * lo * ex, rotb, 1.0_wp, nbox)
         end if
         write (line, '(i0,",",es16.9)') nbox, d
         text = text//trim(line)//new_line("a")
      end do
      call write_text_file(path, text, error)
   end subroutine study_nbox

   !> D_overlap of two bodies (unit scale) by the thesis' reading of N_box: the EOB of their N_ext
   !> extent boxes, then for each body N_box x N_box surface points over the theta and phi range of
   !> its surface inside the EOB, each tested against the other body along the ray to its centre.
   pure function thesis_overlap_depth(body_a, center_a, rot_a, body_b, center_b, rot_b, nbox) result(depth)
      !> First body.
      type(contact_body_type), intent(in) :: body_a
      !> Its centre and rotation (body to world).
      real(wp), intent(in) :: center_a(3), rot_a(3, 3)
      !> Second body.
      type(contact_body_type), intent(in) :: body_b
      !> Its centre and rotation.
      real(wp), intent(in) :: center_b(3), rot_b(3, 3)
      !> Points per angular range (>= 2).
      integer, intent(in) :: nbox
      real(wp) :: depth
      real(wp) :: alo(3), ahi(3), blo(3), bhi(3), lo(3), hi(3)
      call world_box(body_a%ext_lo, body_a%ext_hi, center_a, rot_a, alo, ahi)
      call world_box(body_b%ext_lo, body_b%ext_hi, center_b, rot_b, blo, bhi)
      lo = max(alo, blo)
      hi = min(ahi, bhi)
      depth = 0.0_wp
      if (any(lo > hi)) return
      depth = max(scan_range(body_a, center_a, rot_a, body_b, center_b, rot_b, lo, hi, nbox), &
                  scan_range(body_b, center_b, rot_b, body_a, center_a, rot_a, lo, hi, nbox))
   end function thesis_overlap_depth

   !> Deepest point of body a's surface inside body b over a's EOB angular range (thesis N_box).
   pure function scan_range(a, ca, ra, b, cb, rb, lo, hi, nbox) result(depth)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), cb(3), rb(3, 3), lo(3), hi(3)
      integer, intent(in) :: nbox
      real(wp) :: depth
      real(wp) :: th, ph, x(3), th0, th1, ph0, ph1, step
      integer :: i, j, n
      logical :: any_in
      depth = 0.0_wp
      ! the angular range of the surface inside the EOB, on a 1-degree grid
      step = pi / range_rows
      any_in = .false.
      th0 = pi
      th1 = 0.0_wp
      ph0 = 2.0_wp * pi
      ph1 = 0.0_wp
      do j = 1, 2 * range_rows
         ph = step * (j - 0.5_wp)
         do i = 1, range_rows
            th = step * (i - 0.5_wp)
            x = surface_point(a, ca, ra, th, ph)
            if (any(x < lo) .or. any(x > hi)) cycle
            any_in = .true.
            th0 = min(th0, th)
            th1 = max(th1, th)
            ph0 = min(ph0, ph)
            ph1 = max(ph1, ph)
         end do
      end do
      if (.not. any_in) return
      th0 = max(0.0_wp, th0 - step)
      th1 = min(pi, th1 + step)
      ph0 = max(0.0_wp, ph0 - step)
      ph1 = min(2.0_wp * pi, ph1 + step)
      n = max(2, nbox)
      do j = 0, n - 1
         ph = ph0 + (ph1 - ph0) * j / (n - 1)
         do i = 0, n - 1
            th = th0 + (th1 - th0) * i / (n - 1)
            x = surface_point(a, ca, ra, th, ph)
            if (any(x < lo) .or. any(x > hi)) cycle
            depth = max(depth, depth_in(b, cb, rb, x))
         end do
      end do
   end function scan_range

   !> World surface point of a body (unit scale) in body direction (theta, phi).
   pure function surface_point(a, ca, ra, th, ph) result(x)
      type(contact_body_type), intent(in) :: a
      real(wp), intent(in) :: ca(3), ra(3, 3), th, ph
      real(wp) :: x(3), u(3)
      u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
      x = ca + matmul(ra, a%shape%radius_dir(u) * u)
   end function surface_point

   !> How far the world point x lies inside body b along the ray from b's centre (0 outside).
   pure function depth_in(b, cb, rb, x) result(depth)
      type(contact_body_type), intent(in) :: b
      real(wp), intent(in) :: cb(3), rb(3, 3), x(3)
      real(wp) :: depth, y(3), d
      y = matmul(x - cb, rb)
      d = sqrt(sum(y**2))
      if (d <= 0.0_wp) then
         depth = b%r_min
      else
         depth = max(0.0_wp, b%shape%radius_dir(y) - d)
      end if
   end function depth_in

   !> World box of a body-frame box [lo, hi] (unit scale).
   pure subroutine world_box(lo, hi, c, rot, wlo, whi)
      real(wp), intent(in) :: lo(3), hi(3), c(3), rot(3, 3)
      real(wp), intent(out) :: wlo(3), whi(3)
      real(wp) :: mid(3), half(3)
      mid = c + matmul(rot, 0.5_wp * (lo + hi))
      half = matmul(abs(rot), 0.5_wp * (hi - lo))
      wlo = mid - half
      whi = mid + half
   end subroutine world_box

   subroutine build(body, shape, nused, error)
      type(contact_body_type), intent(out) :: body
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: nused
      type(error_type), allocatable, intent(out) :: error
      if (nused >= 0) then
         call new_contact_body(body, shape, error, nused=nused)
      else
         call new_contact_body(body, shape, error)
      end if
   end subroutine build
end module anm_contact_studies
