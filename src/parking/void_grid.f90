!> Void-targeted placement: a coarse occupancy grid of the box whose cells are marked "blocked"
!> only when no centre inside them can be valid for any particle of the current sieve, so that
!> candidate centres drawn uniformly from the free cells never miss a valid position.
!>
!> A particle of the current sieve contains a ball of radius r_in around its centre (its certified
!> inscribed radius at the smallest width of the sieve). A centre c is therefore invalid when c
!> lies within r_in of a parked particle. A cell of half-diagonal h_d is blocked when its centre
!> lies (a) inside the ball of radius rho_in_j + r_in - h_d around a parked particle j (rho_in_j
!> the particle's own inscribed radius), or (b) inside particle j radially offset by
!> r_in - h_d: |y| <= r_j(y/|y|) + (r_in - h_d)/s_j in j's body frame. Every point of the radial
!> offset lies within that distance of the particle, so in both cases every point of the cell is
!> within r_in of particle j: blocking never excludes a valid centre.
!>
!> Drawing centres uniformly over the free cells and rejecting overlaps therefore accepts positions
!> with exactly the distribution of the thesis' uniform sampling (uniform over the valid set); only
!> fewer attempts are wasted inside occupied space, so a given `max_locations` budget goes further.
!>
!> Usage:
!>     call new_void_grid(vg, box, r_in, max_cells)
!>     call vg%block_particle(shape, center, rot, scale, rho_in, rho_out)
!>     call vg%compact()                    ! rebuild the list of free cells (serial)
!>     x = vg%draw(u1, u2, u3, u4)          ! a uniform point of a uniformly drawn free cell
module anm_parking_void_grid
   use, intrinsic :: iso_fortran_env, only: int8
   use anm_core_kinds, only: wp, i8, pi, two_pi
   use anm_sh_expansion, only: sh_expansion_type
   use anm_contact_body, only: contact_body_type, stored_level, patch_rows, patch_cols, patch_bounds
   use anm_contact_overlap, only: cap_bounds, cap_outside, cap_inside
   implicit none
   private

   public :: void_grid_type, new_void_grid

   !> Answers of `bound_decision`.
   integer, parameter :: undecided = 0, decided_in = 1, decided_out = 2
   !> Edge (cells) of the tiles that `block_particle` decides at once where it can; a tile not
   !> looked at yet.
   integer, parameter :: tile = 4, not_looked = -1

   !> The occupancy grid.
   type :: void_grid_type
      !> Box edges.
      real(wp) :: box(3) = 1.0_wp
      !> Periodic boundaries.
      logical :: periodic = .true.
      !> Cells per edge and cell edges.
      integer :: n(3) = 1
      !> Cell edges (mm).
      real(wp) :: h(3) = 1.0_wp
      !> Inscribed radius of the current sieve's particles (mm).
      real(wp) :: r_in = 0.0_wp
      !> Blocked flag per cell (one byte each: the grid has up to 2^24 cells, and every attempt
      !> reads one flag at random).
      logical(int8), allocatable :: blocked(:)
      !> Free cells (indices into blocked), nfree of them.
      integer, allocatable :: free(:)
      !> Number of free cells listed.
      integer :: nfree = 0
      !> Cells blocked since the last compaction (stale entries of the free list).
      integer :: stale = 0
   contains
      !> True when the cell holding x is blocked.
      procedure :: is_blocked
      !> Block the cells a parked particle makes invalid.
      procedure :: block_particle
      !> Rebuild the list of free cells.
      procedure :: compact
      !> A candidate centre from four uniform deviates.
      procedure :: draw
      !> Fraction of the box that is free.
      procedure :: free_fraction
   end type void_grid_type

contains

   !> A grid for centres of particles with inscribed radius r_in, with at most max_cells cells
   !> (cells are about r_in / 2 wide when that fits).
   pure subroutine new_void_grid(vg, box, periodic, r_in, max_cells)
      !> Grid.
      type(void_grid_type), intent(out) :: vg
      !> Box edges.
      real(wp), intent(in) :: box(3)
      !> Periodic boundaries.
      logical, intent(in) :: periodic
      !> Inscribed radius of the particles to park.
      real(wp), intent(in) :: r_in
      !> Largest number of cells.
      integer, intent(in) :: max_cells
      real(wp) :: h
      integer :: ncell, i1, i2, i3, c(3), d
      logical :: near
      vg%box = box
      vg%periodic = periodic
      vg%r_in = r_in
      h = max(0.5_wp * r_in, (product(box) / real(max_cells, wp))**(1.0_wp / 3.0_wp))
      vg%n = max(1, nint(box / h))
      vg%h = box / vg%n
      ncell = product(vg%n)
      allocate (vg%blocked(ncell), vg%free(ncell))
      vg%blocked = .false.
      ! in a walled box a centre closer than r_in to a wall is invalid: block the cells that lie
      ! entirely that close
      if (.not. periodic) then
         do i3 = 0, vg%n(3) - 1
            do i2 = 0, vg%n(2) - 1
               do i1 = 0, vg%n(1) - 1
                  c = [i1, i2, i3]
                  near = .false.
                  do d = 1, 3
                     if ((c(d) + 1) * vg%h(d) <= r_in .or. c(d) * vg%h(d) >= box(d) - r_in) near = .true.
                  end do
                  if (near) vg%blocked(1 + i1 + vg%n(1) * (i2 + vg%n(2) * i3)) = .true.
               end do
            end do
         end do
      end if
      call vg%compact()
   end subroutine new_void_grid

   !> Mark the cells made invalid by a parked particle (shape in its body frame, pose, inscribed and
   !> bounding radii in mm). With `body` (the contact body of the same expansion), a cell is first
   !> decided by the body's certified bounds of r over the stored patch holding its direction; only
   !> cells whose offset surface passes within those bounds evaluate r (the same cells are blocked).
   pure subroutine block_particle(self, shape, center, rot, scale, rho_in, rho_out, body)
      !> Grid.
      class(void_grid_type), intent(inout) :: self
      !> Particle surface (body frame, shape units).
      type(sh_expansion_type), intent(in) :: shape
      !> Centre (mm), rotation (body to world) and scale.
      real(wp), intent(in) :: center(3), rot(3, 3), scale
      !> Certified inscribed and bounding radii of the particle (mm).
      real(wp), intent(in) :: rho_in, rho_out
      !> Contact body of `shape` (its stored bounds decide most cells without evaluating r).
      type(contact_body_type), intent(in), optional :: body
      real(wp) :: hd, m, reach, x(3), d(3), y(3), ly, ball, off, r2max, q2, q3, w
      integer :: lo(3), hi(3), i1, i2, i3, c1, c2, c3, cell, code, a1, b1, row, nt(3), t1, t2, t3, tt
      logical :: bounds
      integer, allocatable :: tcode(:)
      hd = 0.5_wp * norm2(self%h)
      m = self%r_in - hd
      ball = rho_in + self%r_in - hd
      if (m <= 0.0_wp .and. ball <= 0.0_wp) return
      reach = rho_out + max(m, 0.0_wp)
      off = m / scale
      bounds = .false.
      if (present(body)) bounds = allocated(body%dlo)
      lo = floor((center - reach) / self%h)
      hi = floor((center + reach) / self%h)
      if (.not. self%periodic) then
         lo = max(lo, 0)
         hi = min(hi, self%n - 1)
      end if
      ! tiles of tile^3 cells (from lo) decided at once by the body's bounds over the cap of their
      ! directions, when the first of their cells needs a decision
      if (bounds .and. m > 0.0_wp) then
         nt = (hi - lo) / tile + 1
         allocate (tcode(product(nt)))
         tcode = not_looked
      end if
      ! a cell is blocked only when its centre lies within max(ball, reach) of the particle's
      ! centre (the tests below): cells, rows and planes beyond that (with a margin for the
      ! rounding of the sums) are skipped before any work
      r2max = ball * abs(ball)
      if (m > 0.0_wp) r2max = max(r2max, reach**2)
      r2max = r2max * (1.0_wp + 1.0e-9_wp)
      do i3 = lo(3), hi(3)
         q3 = (((i3 + 0.5_wp) * self%h(3)) - center(3))**2
         if (q3 > r2max) cycle
         c3 = modulo(i3, self%n(3))
         do i2 = lo(2), hi(2)
            q2 = q3 + (((i2 + 0.5_wp) * self%h(2)) - center(2))**2
            if (q2 > r2max) cycle
            c2 = modulo(i2, self%n(2))
            row = 1 + self%n(1) * (c2 + self%n(2) * c3)
            ! the cells of this row within reach, one more on each side
            w = sqrt(r2max - q2)
            a1 = max(lo(1), floor((center(1) - w) / self%h(1)) - 1)
            b1 = min(hi(1), floor((center(1) + w) / self%h(1)) + 1)
            c1 = modulo(a1, self%n(1)) - 1
            do i1 = a1, b1
               c1 = c1 + 1
               if (c1 == self%n(1)) c1 = 0
               cell = row + c1
               if (self%blocked(cell)) cycle
               x = ([i1, i2, i3] + 0.5_wp) * self%h
               d = x - center
               if (sum(d**2) <= ball * abs(ball) .and. ball > 0.0_wp) then
                  self%blocked(cell) = .true.
                  self%stale = self%stale + 1
                  cycle
               end if
               if (m <= 0.0_wp) cycle
               if (sum(d**2) > reach**2) cycle
               if (bounds) then
                  t1 = (i1 - lo(1)) / tile
                  t2 = (i2 - lo(2)) / tile
                  t3 = (i3 - lo(3)) / tile
                  tt = 1 + t1 + nt(1) * (t2 + nt(2) * t3)
                  if (tcode(tt) == not_looked) then
                     tcode(tt) = tile_decision(body, center, rot, scale, self%h, off, lo + tile * [t1, t2, t3], &
                                               min(hi, lo + tile * [t1, t2, t3] + tile - 1))
                  end if
                  if (tcode(tt) == decided_out) cycle
                  if (tcode(tt) == decided_in) then
                     self%blocked(cell) = .true.
                     self%stale = self%stale + 1
                     cycle
                  end if
               end if
               y = matmul(d, rot) / scale
               ly = norm2(y)
               if (ly == 0.0_wp) then
                  self%blocked(cell) = .true.
                  self%stale = self%stale + 1
                  cycle
               end if
               if (bounds) then
                  code = bound_decision(body, y / ly, ly - off)
                  if (code == decided_out) cycle
                  if (code == decided_in) then
                     self%blocked(cell) = .true.
                     self%stale = self%stale + 1
                     cycle
                  end if
               end if
               if (ly <= shape%radius_dir(y / ly) + m / scale) then
                  self%blocked(cell) = .true.
                  self%stale = self%stale + 1
               end if
            end do
         end do
      end do
   end subroutine block_particle

   !> The decision for every cell centre of the tile of cells a..b (unwrapped indices) of a particle
   !> (centre, rotation, scale): `decided_out` when every centre y (body frame) has |y| - off above
   !> r(y/|y|) for sure, `decided_in` when below for sure (the certified bounds of r over the cap of
   !> directions that holds the tile, with bound_decision's margin), else `undecided`.
   pure integer function tile_decision(body, center, rot, scale, h, off, a, b) result(code)
      type(contact_body_type), intent(in) :: body
      real(wp), intent(in) :: center(3), rot(3, 3), scale, h(3), off
      integer, intent(in) :: a(3), b(3)
      real(wp), parameter :: rel = 1.0e-12_wp
      real(wp) :: xlo(3), xhi(3), yc(3), lc, rt, sinb, margin, tlo, thi
      code = undecided
      xlo = (a + 0.5_wp) * h
      xhi = (b + 0.5_wp) * h
      yc = matmul(0.5_wp * (xlo + xhi) - center, rot) / scale
      lc = norm2(yc)
      rt = 0.5_wp * norm2(xhi - xlo) / scale * (1.0_wp + rel)
      if (lc <= 2.0_wp * rt) return
      sinb = rt / lc * (1.0_wp + rel)
      margin = 1.0e-9_wp * body%r_max
      tlo = (lc - rt) * (1.0_wp - rel) - off
      thi = (lc + rt) * (1.0_wp + rel) - off
      select case (cap_bounds(body, yc / lc, sinb, asin(sinb) * (1.0_wp + rel), tlo - margin, thi + margin))
      case (cap_outside)
         code = decided_out
      case (cap_inside)
         code = decided_in
      end select
   end function tile_decision

   !> Whether the certified bounds of r over the stored patch holding the unit direction u decide
   !> the test t <= r(u): `decided_in` (r(u) >= t for sure), `decided_out` (r(u) < t for sure) or
   !> `undecided` (also near a patch edge, where rounding could pick the neighbouring patch). The
   !> margin (1e-9 of r_max) covers the rounding of r(u) as `radius_dir` evaluates it.
   pure integer function bound_decision(body, u, t) result(code)
      type(contact_body_type), intent(in) :: body
      real(wp), intent(in) :: u(3), t
      real(wp), parameter :: edge = 1.0e-9_wp
      real(wp) :: th, ph, ft, fp, rlo, rhi, margin
      integer :: i, j
      code = undecided
      th = atan2(sqrt(u(1)**2 + u(2)**2), u(3)) / pi * patch_rows(stored_level)
      ph = atan2(u(2), u(1))
      if (ph < 0.0_wp) ph = ph + two_pi
      ph = ph / two_pi * patch_cols(stored_level)
      ft = th - aint(th)
      fp = ph - aint(ph)
      if (ft < edge .or. ft > 1.0_wp - edge .or. fp < edge .or. fp > 1.0_wp - edge) return
      i = int(th) + 1
      j = int(ph) + 1
      if (i < 1 .or. i > patch_rows(stored_level) .or. j < 1 .or. j > patch_cols(stored_level)) return
      call patch_bounds(body, stored_level, i, j, rlo, rhi)
      margin = 1.0e-9_wp * body%r_max
      if (t <= rlo - margin) then
         code = decided_in
      else if (t > rhi + margin) then
         code = decided_out
      end if
   end function bound_decision

   !> Rebuild the list of free cells (in cell order, so that draws are reproducible).
   pure subroutine compact(self)
      !> Grid.
      class(void_grid_type), intent(inout) :: self
      integer :: k
      self%nfree = 0
      self%stale = 0
      do k = 1, size(self%blocked)
         if (.not. self%blocked(k)) then
            self%nfree = self%nfree + 1
            self%free(self%nfree) = k
         end if
      end do
   end subroutine compact

   !> A uniform point of a uniformly drawn free cell, from four uniform deviates in [0, 1).
   pure function draw(self, u1, u2, u3, u4) result(x)
      !> Grid.
      class(void_grid_type), intent(in) :: self
      !> Uniform deviates.
      real(wp), intent(in) :: u1, u2, u3, u4
      real(wp) :: x(3)
      integer :: k, cell, c(3)
      k = min(self%nfree, 1 + int(u1 * self%nfree))
      cell = self%free(k) - 1
      c(1) = mod(cell, self%n(1))
      c(2) = mod(cell / self%n(1), self%n(2))
      c(3) = cell / (self%n(1) * self%n(2))
      x = (c + [u2, u3, u4]) * self%h
   end function draw

   !> True when the cell holding the point x (inside the box) is blocked.
   pure logical function is_blocked(self, x) result(b)
      !> Grid.
      class(void_grid_type), intent(in) :: self
      !> Point.
      real(wp), intent(in) :: x(3)
      integer :: c(3)
      c = min(self%n - 1, max(0, int(x / self%h)))
      b = self%blocked(1 + c(1) + self%n(1) * (c(2) + self%n(2) * c(3)))
   end function is_blocked

   !> Fraction of the cells that are free.
   pure function free_fraction(self) result(f)
      !> Grid.
      class(void_grid_type), intent(in) :: self
      real(wp) :: f
      f = real(self%nfree, wp) / real(size(self%blocked), wp)
   end function free_fraction
end module anm_parking_void_grid
