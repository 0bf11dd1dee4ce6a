!> `anm verify`: an audit of a model file that shares nothing with the parking path but the SH
!> evaluation. Every pair of particles whose bounding spheres intersect (periodic images included)
!> is checked by dense point sampling both ways: the surface points of A on a latitude-longitude
!> grid of `resolution` x 2 `resolution` directions that fall inside B's bounding sphere are mapped
!> to B's body frame and tested against r_B; the penetration of a point is r_B(y/|y|) - |y| (radial,
!> in mm). In non-periodic boxes every surface point must lie inside the box.
!>
!> Bounding radii are the largest sampled radius on the sampling grid times 1.02, or the largest
!> cube-map bound of r (below) when that is larger.
!>
!> Pruning (the result is the same as testing every sample): each (shape, order) of B has a
!> cube-map table of proven upper bounds of r_B over cells of directions (anm_audit_bounds: r at
!> the cell corners plus a curvature allowance from Bernstein's inequality, about 6e-3 of the mean
!> radius). A's samples are grouped in blocks of 6 x 6 and superblocks of 4 x 4 blocks, each with
!> a bounding ball. A ball of A's samples (all of A, then each superblock, then each block) is
!> skipped when, seen from B's centre, it lies beyond the bounds of every cell its cap of
!> directions meets; a single sample is skipped when it lies beyond its own cell's bound (or could
!> not be deeper than the depth found so far). Only samples that pass are evaluated exactly. A sand
!> grain beside a 10 mm aggregate thus costs a few bound look-ups instead of thousands of
!> evaluations of the aggregate's order-14 surface.
!>
!> Certified first filter (default): each (shape, order) also gets the contact body the engine
!> uses (anm_contact_body), and a pair is sampled only when the certified contact test
!> (`bodies_overlap` with `certified = .true.`) cannot prove it disjoint. A pair it clears is
!> disjoint (guaranteed to rounding, docs/contact.md); every overlap and depth reported still
!> comes from the dense sampling alone. `filter = .false.` samples every pair (the audit fully
!> independent of the contact code). By default a (shape, order) gets its body only when it takes
!> part in at least `min_filter_ends` pairs (a body costs about as much as sampling 1,000 near
!> pairs of sand grains); the report is the same either way but for `pairs_cleared`.
!>
!> Distributed (the MPI build): with a `verify_split_type`, process r of n audits the pairs whose
!> later particle (the loop index, p >= q) has its centre in the slab r of n equal slabs along x,
!> and the walls of those particles; `reduce` then combines the reports of all processes, which
!> are the serial report (counts summed, the largest penetration and its pair from the process
!> that found it).
!>
!> Usage:
!>     call verify_model(model, 120, report)
module anm_audit_verify
   use anm_core_kinds, only: wp, pi, i8
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_io_model, only: model_type
   use anm_neighbours_cell_list, only: cell_list_type, new_cell_list
   use anm_core_error, only: error_type
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_contact_overlap, only: contact_params_type, bodies_overlap
   use anm_audit_bounds, only: radius_bounds_type, new_radius_bounds, max_bound_cells, bound_at, ball_beyond
   implicit none
   private

   public :: verify_report_type, verify_model, verify_memory, verify_split_type, owner_slab

   !> Result of an audit.
   type :: verify_report_type
      !> Pairs whose bounding spheres intersect (checked by sampling).
      integer(i8) :: pairs_checked = 0
      !> Of these, pairs the certified contact test proved disjoint (not sampled).
      integer(i8) :: pairs_cleared = 0
      !> Pairs with a penetration above the tolerance.
      integer(i8) :: overlapping_pairs = 0
      !> Particles crossing a wall (non-periodic boxes).
      integer :: wall_violations = 0
      !> Largest penetration found (mm), between particles or through a wall.
      real(wp) :: max_depth = 0.0_wp
      !> Particles of the worst pair between particles (0 if none) and its penetration (mm).
      integer :: worst(2) = 0
      real(wp) :: worst_depth = 0.0_wp
      !> Tolerance used (mm).
      real(wp) :: tolerance = 0.0_wp
      !> Directions sampled per particle.
      integer :: samples = 0
   end type verify_report_type

   !> The processes that audit one model together (the MPI build extends it: mpi/src/verify.f90):
   !> this process audits the pairs of its slab, and `reduce` combines the reports.
   type, abstract :: verify_split_type
      !> This process and the number of processes.
      integer :: rank = 0, nranks = 1
   contains
      !> The report of all processes from each one's (collective; the same on every process).
      procedure(split_reduce), deferred :: reduce
   end type verify_split_type

   abstract interface
      subroutine split_reduce(self, report)
         import :: verify_split_type, verify_report_type
         !> Processes.
         class(verify_split_type), intent(in) :: self
         !> This process' report on entry, the combined one on return.
         type(verify_report_type), intent(inout) :: report
      end subroutine split_reduce
   end interface

   !> Per (shape, order): surface sampled on a latitude-longitude grid of cell centres
   !> theta_i = pi (i - 1/2)/nt, phi_j = 2 pi (j - 1/2)/np, the bounding radius (shape units), and
   !> the cube-map table of upper bounds of r (see `build_bounds`).
   type :: sampled_type
      integer :: shape = 0, order = -1
      type(sh_expansion_type) :: s
      integer :: nt = 0, np = 0
      real(wp), allocatable :: x(:, :, :)   ! (3, nt, np) surface points
      real(wp) :: rmax = 0.0_wp
      !> Blocks of block x block samples: bounding ball centre (3, nbt, nbp) and radius.
      integer :: nbt = 0, nbp = 0
      real(wp), allocatable :: bc(:, :, :), br(:, :)
      !> The samples of each block stored together (3, block**2, nbt, nbp); a block at the grid's
      !> edge repeats its first sample (a repeated sample changes no depth).
      real(wp), allocatable :: xb(:, :, :, :)
      !> Superblocks of super x super blocks: bounding ball centre (3, nst, nsp) and radius.
      integer :: nst = 0, nsp = 0
      real(wp), allocatable :: sc(:, :, :), sr(:, :)
      !> Upper bounds of r over cells of directions.
      type(radius_bounds_type) :: bounds
   end type sampled_type

   !> Samples per block edge, blocks per superblock edge.
   integer, parameter :: block = 6, super = 4
   !> Pairs (ends) of a (shape, order) from which its contact body is built for the filter.
   integer, parameter :: min_filter_ends = 1000
   !> Curvature allowance of the radius bounds relative to the mean radius (finer tables prune a
   !> little more but cost more to look up: 6e-3 took the fewest instructions on a reduced M_sand).
   real(wp), parameter :: bound_slack = 6.0e-3_wp

contains

   !> Audit `model` at `resolution` polar samples; penetrations deeper than `tolerance` mm
   !> (default 1e-4 of the smallest sieve width) count as overlaps.
   !> Length: about 150 lines: the set-up (samples, cell list, filter bodies) and the one parallel pair
   !> loop share their arrays; the pieces that stand alone (bodies, ends, walls, slabs) are helpers.
   subroutine verify_model(model, resolution, report, tolerance, prune, filter, split)
      !> Model.
      type(model_type), intent(in) :: model
      !> Polar samples per particle (azimuthal: twice as many).
      integer, intent(in) :: resolution
      !> Result.
      type(verify_report_type), intent(out) :: report
      !> Tolerance (mm).
      real(wp), intent(in), optional :: tolerance
      !> Skip the samples that the block bounds place outside the other particle (default true;
      !> false tests every sample, for checking the pruning).
      logical, intent(in), optional :: prune
      !> Skip the pairs the certified contact test proves disjoint (true: for every (shape, order);
      !> false: sample every pair whose bounding spheres intersect; default: for the (shape, order)
      !> pairs that take part in at least min_filter_ends pairs).
      logical, intent(in), optional :: filter
      !> Processes auditing the model together (each its slab; the report combined).
      class(verify_split_type), intent(in), optional :: split
      type(sampled_type), allocatable :: samp(:)
      type(contact_body_type), allocatable :: bodies(:)
      logical, allocatable :: has_body(:)
      type(contact_params_type) :: cparams
      integer, allocatable :: key(:), kshape(:), korder(:)
      real(wp), allocatable :: rho(:), cw(:, :)
      type(cell_list_type) :: cl
      integer :: p, k, nkey
      integer(i8) :: npairs, nover, ncleared
      real(wp) :: depth_max, worst_depth
      integer :: nwall
      logical :: pruned, filtered
      integer, allocatable :: ends(:)
      integer :: rank, nranks

      rank = 0
      nranks = 1
      if (present(split)) then
         rank = split%rank
         nranks = split%nranks
      end if
      pruned = .true.
      if (present(prune)) pruned = prune
      filtered = .true.
      if (present(filter)) filtered = filter
      cparams%certified = .true.
      report%samples = 2 * resolution**2
      if (present(tolerance)) then
         report%tolerance = tolerance
      else if (allocated(model%min_width)) then
         report%tolerance = 1.0e-4_wp * minval(model%min_width)
      end if
      call shape_keys(model, key, kshape, korder, nkey)
      allocate (samp(nkey))
      samp%shape = kshape(:nkey)
      samp%order = korder(:nkey)
      !$omp parallel do default(none) shared(samp, nkey, model, resolution) private(k) schedule(dynamic)
      do k = 1, nkey
         call sample_shape(model%shapes(samp(k)%shape), samp(k)%order, resolution, samp(k))
      end do
      !$omp end parallel do
      allocate (rho(model%np))
      do p = 1, model%np
         rho(p) = samp(key(p))%rmax * model%scale(p)
      end do
      ! the centres wrapped into the box, shared by the threads; the cell list's block pool sized
      ! for the particles at once (a block per particle at most; blocks not used cost no memory)
      allocate (cw(3, model%np))
      do p = 1, model%np
         cw(:, p) = wrap(model, model%center(:, p))
      end do
      call new_cell_list(cl, model%box, model%periodic, max(minval(rho, mask=rho > 0), 1.0e-6_wp), &
                         capacity=2 * model%np)
      do p = 1, model%np
         call cl%insert(p, cw(:, p), rho(p))
      end do
      ! which (shape, order) pairs get a contact body for the filter
      allocate (ends(nkey), has_body(nkey))
      ends = 0
      if (filtered .and. .not. present(filter)) call count_ends(model, key, rho, cl, cw, ends)
      if (present(filter)) ends = merge(min_filter_ends, 0, filtered)
      call build_bodies(model, samp, ends, bodies, has_body)
      npairs = 0
      ncleared = 0
      nover = 0
      depth_max = 0.0_wp
      worst_depth = 0.0_wp
      nwall = 0
      !$omp parallel default(none) shared(model, samp, key, rho, cl, cw, report, worst_depth, pruned, bodies, &
      !$omp& has_body, cparams, rank, nranks) private(p) reduction(+:npairs, nover, nwall, ncleared) reduction(max:depth_max)
      block
         integer, allocatable :: cand(:)
         real(wp), allocatable :: shift(:, :)
         integer :: ncand, i, q
         real(wp) :: d, dw, pair_max
         logical :: hit
         pair_max = 0.0_wp
         !$omp do schedule(dynamic, 16)
         do p = 1, model%np
            if (owner_slab(cw(1, p), model%box(1), nranks) /= rank) cycle   ! this process' slab
            if (.not. model%periodic) then
               dw = wall_depth(model, samp, key, p)
               if (dw > report%tolerance) nwall = nwall + 1
               if (dw > depth_max) depth_max = dw
            end if
            ! each pair once: (p, q + s) and (q, p - s) are the same pair, so only q <= p (a large
            ! particle, parked first, then shares its many pairs with the small ones instead of
            ! keeping them all on one thread); a particle may meet its own periodic image in a box
            ! smaller than twice its size
            call cl%neighbours(cw(:, p), rho(p), cand, shift, ncand, hit, jmax=p)
            do i = 1, ncand
               q = cand(i)
               ! the stored radii are rounded up: the exact bounding-sphere test
               if (sum((cw(:, q) + shift(:, i) - cw(:, p))**2) >= (rho(p) + rho(q))**2) cycle
               if (q == p) then
                  if (all(shift(:, i) == 0.0_wp)) cycle
                  if (.not. positive(shift(:, i))) cycle
               end if
               npairs = npairs + 1
               if (has_body(key(p)) .and. has_body(key(q))) then
                  if (.not. bodies_overlap(bodies(key(p)), cw(:, p), model%rotation(:, :, p), model%scale(p), &
                                           bodies(key(q)), cw(:, q) + shift(:, i), model%rotation(:, :, q), &
                                           model%scale(q), cparams)) then
                     ncleared = ncleared + 1
                     cycle
                  end if
               end if
               d = max(pair_depth(model, samp, key, rho, pruned, p, cw(:, p), q, cw(:, q) + shift(:, i)), &
                       pair_depth(model, samp, key, rho, pruned, q, cw(:, q) + shift(:, i), p, cw(:, p)))
               if (d > report%tolerance) nover = nover + 1
               if (d > depth_max) depth_max = d
               ! the deepest pair between particles (walls apart, which depth_max also holds)
               if (d > pair_max) then
                  pair_max = d
                  !$omp critical (verify_worst)
                  if (d > worst_depth) then
                     worst_depth = d
                     report%worst = [q, p]
                  end if
                  !$omp end critical (verify_worst)
               end if
            end do
         end do
         !$omp end do
      end block
      !$omp end parallel
      report%pairs_checked = npairs
      report%pairs_cleared = ncleared
      report%overlapping_pairs = nover
      report%wall_violations = nwall
      report%max_depth = depth_max
      report%worst_depth = worst_depth
      if (present(split)) call split%reduce(report)
   end subroutine verify_model

   !> The slab (0 .. nslab - 1) of n equal slabs along an edge of length `length` holding
   !> coordinate x (wrapped into the box).
   pure integer function owner_slab(x, length, nslab) result(r)
      !> Coordinate (mm) and edge length (mm).
      real(wp), intent(in) :: x, length
      !> Number of slabs.
      integer, intent(in) :: nslab
      r = max(0, min(nslab - 1, int(x / length * nslab)))
   end function owner_slab

   !> The contact bodies of the (shape, order) pairs with at least min_filter_ends pair ends, for
   !> the certified filter (has_body false for the others and for shapes the contact code cannot
   !> certify, which are always sampled).
   subroutine build_bodies(model, samp, ends, bodies, has_body)
      type(model_type), intent(in) :: model
      type(sampled_type), intent(in) :: samp(:)
      integer, intent(in) :: ends(:)
      type(contact_body_type), allocatable, intent(out) :: bodies(:)
      logical, intent(out) :: has_body(:)
      integer :: k, nkey
      nkey = size(samp)
      allocate (bodies(nkey))
      has_body = .false.
      !$omp parallel do default(none) shared(samp, nkey, model, bodies, has_body, ends) private(k) schedule(dynamic)
      do k = 1, nkey
         if (ends(k) < min_filter_ends) cycle
         block
            type(error_type), allocatable :: berr
            ! a shape the contact code cannot certify (not star-shaped) is always sampled
            call new_contact_body(bodies(k), model%shapes(samp(k)%shape), berr, nused=samp(k)%order)
            has_body(k) = .not. allocated(berr)
         end block
      end do
      !$omp end parallel do
   end subroutine build_bodies

   !> Per (shape, order): the number of pair ends (pairs whose bounding spheres intersect, each
   !> counted for both particles' (shape, order)).
   subroutine count_ends(model, key, rho, cl, cw, ends)
      type(model_type), intent(in) :: model
      integer, intent(in) :: key(:)
      real(wp), intent(in) :: rho(:)
      type(cell_list_type), intent(in) :: cl
      !> Centres wrapped into the box.
      real(wp), intent(in) :: cw(:, :)
      integer, intent(inout) :: ends(:)
      integer :: p
      !$omp parallel default(none) shared(model, key, rho, cl, cw) private(p) reduction(+:ends)
      block
         integer, allocatable :: cand(:)
         real(wp), allocatable :: shift(:, :)
         integer :: ncand, i, q
         logical :: hit
         !$omp do schedule(dynamic, 64)
         do p = 1, model%np
            call cl%neighbours(cw(:, p), rho(p), cand, shift, ncand, hit, jmax=p)
            do i = 1, ncand
               q = cand(i)
               if (sum((cw(:, q) + shift(:, i) - cw(:, p))**2) >= (rho(p) + rho(q))**2) cycle
               if (q == p) cycle
               ends(key(p)) = ends(key(p)) + 1
               ends(key(q)) = ends(key(q)) + 1
            end do
         end do
         !$omp end do
      end block
      !$omp end parallel
   end subroutine count_ends

   !> The distinct (shape, order) pairs of a model (few: one sampled surface each) and the pair of
   !> each particle.
   pure subroutine shape_keys(model, key, kshape, korder, nkey)
      !> Model.
      type(model_type), intent(in) :: model
      !> Pair of each particle (1..nkey).
      integer, allocatable, intent(out) :: key(:)
      !> Shape and order of each pair (entries beyond nkey unused).
      integer, allocatable, intent(out) :: kshape(:), korder(:)
      !> Number of pairs.
      integer, intent(out) :: nkey
      integer :: p, k
      allocate (key(model%np), kshape(16), korder(16))
      nkey = 0
      do p = 1, model%np
         key(p) = 0
         do k = 1, nkey
            if (kshape(k) == model%shape(p) .and. korder(k) == model%nmax(p)) then
               key(p) = k
               exit
            end if
         end do
         if (key(p) == 0) then
            if (nkey == size(kshape)) then
               kshape = [kshape, kshape]
               korder = [korder, korder]
            end if
            nkey = nkey + 1
            kshape(nkey) = model%shape(p)
            korder(nkey) = model%nmax(p)
            key(p) = nkey
         end if
      end do
   end subroutine shape_keys

   !> Whether a periodic shift is lexicographically positive (each self-image pair once).
   pure logical function positive(v)
      !> Shift.
      real(wp), intent(in) :: v(3)
      positive = v(1) > 0.0_wp .or. (v(1) == 0.0_wp .and. (v(2) > 0.0_wp .or. (v(2) == 0.0_wp .and. v(3) > 0.0_wp)))
   end function positive

   !> A centre wrapped into the box when the model is periodic.
   pure function wrap(model, c) result(w)
      !> Model.
      type(model_type), intent(in) :: model
      !> Centre.
      real(wp), intent(in) :: c(3)
      real(wp) :: w(3)
      if (model%periodic) then
         w = modulo(c, model%box)
      else
         w = c
      end if
   end function wrap

   !> Largest radial penetration of A's sampled surface points into B (mm), 0 if none. Only
   !> the blocks of samples whose bounding balls meet B's bounding sphere are visited.
   function pair_depth(model, samp, key, rho, pruned, a, ca, b, cb) result(depth)
      !> Model.
      type(model_type), intent(in) :: model
      !> Sampled surfaces, the sampled surface of each particle, bounding radii (mm).
      type(sampled_type), intent(in) :: samp(:)
      integer, intent(in) :: key(:)
      real(wp), intent(in) :: rho(:)
      !> Skip the samples that the block bounds place outside B.
      logical, intent(in) :: pruned
      !> Particles A and B and their (image) centres.
      integer, intent(in) :: a, b
      real(wp), intent(in) :: ca(3), cb(3)
      real(wp) :: depth, x(3), y(3), ly, sa, sb, m(3, 3), t(3), d(3), rb, rb2
      integer :: i, j, ib, jb, jbw, ib0, ib1, jb0, jb1, is, js
      integer :: sstate(samp(key(a))%nst, samp(key(a))%nsp)
      depth = 0.0_wp
      sa = model%scale(a)
      sb = model%scale(b)
      associate (sp => samp(key(a)), sq => samp(key(b)))
         ! B's centre and bounding radius in A's body frame (A's shape units)
         d = matmul(cb - ca, model%rotation(:, :, a)) / sa
         rb = rho(b) / sa
         rb2 = rb * rb
         ! A body -> B body: y = m x + t
         m = matmul(transpose(model%rotation(:, :, b)), model%rotation(:, :, a)) * (sa / sb)
         t = matmul(ca - cb, model%rotation(:, :, b)) / sb
         ib0 = 1
         ib1 = sp%nbt
         jb0 = 1
         jb1 = sp%nbp
         if (pruned) then
            ! all of A (inside its bounding sphere) beyond B's surface
            if (ball_beyond(sq%bounds, t, rho(a) / sb)) return
            ! only A's blocks whose directions meet B's bounding sphere
            call cap_blocks(sp, d, rb, ib0, ib1, jb0, jb1)
         end if
         ! superblocks: 0 not yet tested, 1 to visit, 2 skipped
         sstate = 0
         do jbw = jb0, jb1
            jb = 1 + modulo(jbw - 1, sp%nbp)
            do ib = ib0, ib1
               is = (ib - 1) / super + 1
               js = (jb - 1) / super + 1
               if (sstate(is, js) == 0) then
                  sstate(is, js) = 1
                  if (sum((sp%sc(:, is, js) - d)**2) >= (rb + sp%sr(is, js))**2) then
                     sstate(is, js) = 2
                  else if (pruned) then
                     if (ball_beyond(sq%bounds, matmul(m, sp%sc(:, is, js)) + t, sp%sr(is, js) * sa / sb)) sstate(is, js) = 2
                  end if
               end if
               if (sstate(is, js) == 2) cycle
               if (sum((sp%bc(:, ib, jb) - d)**2) >= (rb + sp%br(ib, jb))**2) cycle
               if (pruned) then
                  if (ball_beyond(sq%bounds, matmul(m, sp%bc(:, ib, jb)) + t, sp%br(ib, jb) * sa / sb)) cycle
               end if
               do i = 1, block * block
                  x = sp%xb(:, i, ib, jb)
                  if (sum((x - d)**2) >= rb2) cycle
                  y = matmul(m, x) + t
                  ly = norm2(y)
                  ! r_B cannot reach this point deeper than the depth found so far
                  if (pruned .and. ly > 0.0_wp) then
                     if (bound_at(sq%bounds, y) - ly <= depth / sb) cycle
                  end if
                  if (ly == 0.0_wp) then
                     depth = max(depth, sb * sq%s%radius_dir([0.0_wp, 0.0_wp, 1.0_wp]))
                  else
                     depth = max(depth, sb * (sq%s%radius_dir(y / ly) - ly))
                  end if
               end do
            end do
         end do
      end associate
   end function pair_depth

   !> How far the sampled surface of particle a leaves the box (mm), 0 if inside.
   function wall_depth(model, samp, key, a) result(depth)
      !> Model.
      type(model_type), intent(in) :: model
      !> Sampled surfaces, the sampled surface of each particle.
      type(sampled_type), intent(in) :: samp(:)
      integer, intent(in) :: key(:)
      !> Particle.
      integer, intent(in) :: a
      real(wp) :: depth, x(3)
      integer :: i, j
      depth = 0.0_wp
      associate (sp => samp(key(a)))
         do j = 1, sp%np
            do i = 1, sp%nt
               x = model%center(:, a) + model%scale(a) * matmul(model%rotation(:, :, a), sp%x(:, i, j))
               depth = max(depth, maxval(-x), maxval(x - model%box))
            end do
         end do
      end associate
   end function wall_depth

   !> Memory (bytes) verify_model needs at `resolution`: per distinct (shape, order) pair the
   !> 2 resolution**2 sampled surface points, their blocks and the cube-map bounds of r, plus per particle the model
   !> (about 120 bytes), its key, bounding radius, wrapped centre and cell-list record, and the
   !> read's temporary rotation (about 320 bytes in all, rounded up); with the certified
   !> filter (default) also one contact body (about 4.5 MB) per pair.
   function verify_memory(model, resolution, filter) result(bytes)
      !> Model (validated).
      type(model_type), intent(in) :: model
      !> Polar samples (as verify_model).
      integer, intent(in) :: resolution
      !> Certified filter (as verify_model, default true).
      logical, intent(in), optional :: filter
      real(wp) :: bytes
      logical, allocatable :: seen(:, :)
      integer :: p, nkey, maxorder
      maxorder = 0
      if (model%np > 0) maxorder = maxval(model%nmax(:model%np))
      allocate (seen(size(model%shapes), 0:maxorder))
      seen = .false.
      do p = 1, model%np
         seen(model%shape(p), model%nmax(p)) = .true.
      end do
      nkey = count(seen)
      bytes = 16.0e6_wp + real(nkey, wp) * 2.0_wp * real(resolution, wp)**2 * (48.0_wp + 32.0_wp / block**2) &
              + real(nkey, wp) * 48.0_wp * real(max_bound_cells + 1, wp)**2 + real(model%np, wp) * 320.0_wp
      if (.not. present(filter)) then
         bytes = bytes + real(nkey, wp) * 5.0e6_wp
      else if (filter) then
         bytes = bytes + real(nkey, wp) * 5.0e6_wp
      end if
   end function verify_memory

   !> The blocks whose directions meet the cap of directions of the ball (c, r) seen from the
   !> origin: rows ib0..ib1, columns jb0..jb1 (columns modulo nbp; every block when the ball holds
   !> the origin).
   pure subroutine cap_blocks(sq, c, r, ib0, ib1, jb0, jb1)
      type(sampled_type), intent(in) :: sq
      real(wp), intent(in) :: c(3), r
      integer, intent(out) :: ib0, ib1, jb0, jb1
      real(wp) :: lc, alpha, th, ph, t0, t1, dphi, wt, wp_
      ib0 = 1
      ib1 = sq%nbt
      jb0 = 1
      jb1 = sq%nbp
      lc = norm2(c)
      if (lc <= r) return
      alpha = asin(r / lc)
      th = acos(max(-1.0_wp, min(1.0_wp, c(3) / lc)))
      ph = atan2(c(2), c(1))
      if (ph < 0.0_wp) ph = ph + 2.0_wp * pi
      wt = block * pi / sq%nt
      wp_ = block * 2.0_wp * pi / sq%np
      t0 = th - alpha
      t1 = th + alpha
      ib0 = max(1, floor(t0 / wt) + 1)
      ib1 = min(sq%nbt, floor(t1 / wt) + 1)
      jb0 = 1
      jb1 = sq%nbp
      if (t0 > 0.0_wp .and. t1 < pi) then
         ! the cap holds no pole: its azimuths lie within asin(sin alpha / sin theta) of phi
         dphi = asin(min(1.0_wp, sin(alpha) / sin(th)))
         jb0 = floor((ph - dphi) / wp_) + 1
         jb1 = floor((ph + dphi) / wp_) + 1
         if (jb1 - jb0 + 1 >= sq%nbp) then
            jb0 = 1
            jb1 = sq%nbp
         end if
      end if
   end subroutine cap_blocks

   subroutine sample_shape(shape, order, resolution, samp)
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: order, resolution
      type(sampled_type), intent(inout) :: samp
      real(wp) :: th, ph, u(3), r, c(3), rr
      integer :: i, j, ib, jb
      samp%s = sh_truncate(shape, order)
      samp%nt = resolution
      samp%np = 2 * resolution
      allocate (samp%x(3, samp%nt, samp%np))
      samp%rmax = 0.0_wp
      do j = 1, samp%np
         ph = 2.0_wp * pi * (j - 0.5_wp) / samp%np
         do i = 1, samp%nt
            th = pi * (i - 0.5_wp) / samp%nt
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            r = samp%s%radius_dir(u)
            samp%x(:, i, j) = r * u
            samp%rmax = max(samp%rmax, r)
         end do
      end do
      ! bounding radius: the largest sample times a margin far above the variation of r within
      ! one grid cell at the orders used (checked against a grid twice as fine in the tests)
      samp%rmax = 1.02_wp * samp%rmax
      samp%nbt = (samp%nt + block - 1) / block
      samp%nbp = (samp%np + block - 1) / block
      allocate (samp%bc(3, samp%nbt, samp%nbp), samp%br(samp%nbt, samp%nbp), &
                samp%xb(3, block * block, samp%nbt, samp%nbp))
      do jb = 1, samp%nbp
         do ib = 1, samp%nbt
            associate (pts => samp%x(:, (ib - 1) * block + 1:min(samp%nt, ib * block), &
                                     (jb - 1) * block + 1:min(samp%np, jb * block)))
               call centred_ball(pts, c, rr)
               samp%bc(:, ib, jb) = c
               samp%br(ib, jb) = rr
               samp%xb(:, :, ib, jb) = spread(pts(:, 1, 1), 2, block * block)
               samp%xb(:, :size(pts, 2) * size(pts, 3), ib, jb) = reshape(pts, [3, size(pts, 2) * size(pts, 3)])
            end associate
         end do
      end do
      samp%nst = (samp%nbt + super - 1) / super
      samp%nsp = (samp%nbp + super - 1) / super
      allocate (samp%sc(3, samp%nst, samp%nsp), samp%sr(samp%nst, samp%nsp))
      do jb = 1, samp%nsp
         do ib = 1, samp%nst
            associate (pts => samp%x(:, (ib - 1) * block * super + 1:min(samp%nt, ib * block * super), &
                                     (jb - 1) * block * super + 1:min(samp%np, jb * block * super)))
               call centred_ball(pts, c, rr)
               samp%sc(:, ib, jb) = c
               samp%sr(ib, jb) = rr
            end associate
         end do
      end do
      call new_radius_bounds(samp%bounds, samp%s, bound_slack)
      samp%rmax = max(samp%rmax, samp%bounds%umax)
   end subroutine sample_shape

   !> The ball about the mean c of the points pts(3, :, :) that holds them all (radius rr).
   pure subroutine centred_ball(pts, c, rr)
      real(wp), intent(in) :: pts(:, :, :)
      real(wp), intent(out) :: c(3), rr
      integer :: i, j
      c = sum(sum(pts, dim=3), dim=2) / real(size(pts, 2) * size(pts, 3), wp)
      rr = 0.0_wp
      do j = 1, size(pts, 3)
         do i = 1, size(pts, 2)
            rr = max(rr, norm2(pts(:, i, j) - c))
         end do
      end do
   end subroutine centred_ball
end module anm_audit_verify
